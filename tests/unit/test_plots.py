"""tools/plots.py: the delivery plots from a small synthetic route (no ROS), and its pure helpers."""
from __future__ import annotations

import importlib.util
import json
import math
import sys
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

ROOT = Path(__file__).resolve().parents[2]
HOTEL_MAP = ROOT / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"


def _load(name: str):
    spec = importlib.util.spec_from_file_location(f"chefbot_tools_{name}", ROOT / "tools" / f"{name}.py")
    mod = importlib.util.module_from_spec(spec)
    sys.modules[spec.name] = mod
    spec.loader.exec_module(mod)
    return mod


plots = _load("plots")


def _route(tmp_path: Path, map_file: Path = HOTEL_MAP) -> Path:
    """Two legs (home -> table_1 -> home) at 5 Hz; the estimate lags 2 cm behind and is missing at first."""
    t = np.arange(0.0, 20.0, 0.2) + 100.0
    s = (t - t[0]) / 10.0
    x = np.where(s <= 1, 2.05 * s, 2.05 * (2 - s))
    y = np.where(s <= 1, -3.0 * s, -3.0 * (2 - s))
    yaw = np.full_like(t, -0.97)
    truth = np.stack([x, y, yaw], axis=1)
    est = truth + [0.02, 0.0, 0.01]
    estimate = [None if i < 3 else list(e) for i, e in enumerate(est)]
    legs = [{"name": "table_1", "goal": [2.05, -3.0, 0.0], "t_start": 100.0, "t_end": 110.0,
             "plan": [[0, 0], [1, -1.5], [2.05, -3.0]]},
            {"name": "home", "goal": [0.0, 0.0, 0.0], "t_start": 110.0, "t_end": 119.8,
             "plan": [[2.05, -3.0], [0, 0]]}]
    (tmp_path / "trajectory.json").write_text(json.dumps(
        {"map_file": str(map_file), "estimate_source": "tf map -> base_footprint",
         "samples": {"t": t.tolist(), "truth": truth.tolist(), "estimate": estimate}, "legs": legs}))
    (tmp_path / "delivery.json").write_text(json.dumps(
        {"legs": [{"name": "table_1", "ok": True, "state": "SUCCEEDED", "seconds": 10.0, "limit_s": 9.0},
                  {"name": "home", "ok": False, "state": "ABORTED", "seconds": 9.8, "limit_s": float("nan")}]}))
    return tmp_path


def test_write_plots_makes_three_nonempty_pngs(tmp_path: Path) -> None:
    paths = plots.write_plots(_route(tmp_path))
    assert [p.name for p in paths] == list(plots.PLOT_NAMES)
    for p in paths:
        with Image.open(p) as im:
            assert im.format == "PNG"
            assert im.width >= 600 and im.height >= 400, (p.name, im.size)
            px = np.asarray(im.convert("L"))
        # not blank: a real drawing has many distinct grey levels and dark ink
        assert len(np.unique(px)) > 20, p.name
        assert (px < 100).mean() > 0.001, p.name


def test_trajectory_plot_draws_the_route_in_colour(tmp_path: Path) -> None:
    """The map alone is grey: the truth (blue) and estimate (orange) must add coloured pixels."""
    out = plots.write_plots(_route(tmp_path))[0]
    rgb = np.asarray(Image.open(out).convert("RGB")).astype(int)
    plot_area = rgb[: int(0.85 * rgb.shape[0])]          # above the legend
    assert (np.ptp(plot_area, axis=2) > 80).sum() > 300


def test_pose_at_interpolates_and_refuses_far_stamps() -> None:
    hist = [(0.0, 0.0, 0.0, math.pi - 0.1), (1.0, 1.0, 2.0, -math.pi + 0.1)]
    x, y, yaw = plots.pose_at(hist, 0.5, max_gap=1.0)
    assert (x, y) == pytest.approx((0.5, 1.0))
    assert abs(abs(yaw) - math.pi) < 1e-9          # across the ±pi seam, not through 0
    assert plots.pose_at(hist, 1.1, max_gap=1.0) == pytest.approx((1.0, 2.0, -math.pi + 0.1))
    assert plots.pose_at(hist, 5.0, max_gap=1.0) is None
    assert plots.pose_at(hist, float("nan")) is None
    assert plots.pose_at([], 0.0) is None
    gap = [(0.0, 0.0, 0.0, 0.0), (10.0, 1.0, 0.0, 0.0)]
    assert plots.pose_at(gap, 5.0) is None


def test_localization_error_wraps_heading_and_keeps_missing_as_nan() -> None:
    truth = np.array([[0.0, 0.0, math.pi - 0.05], [1.0, 1.0, 0.0]])
    est = np.array([[0.3, 0.4, -math.pi + 0.05], [np.nan] * 3])
    xy, dyaw = plots.localization_error(truth, est)
    assert xy[0] == pytest.approx(0.5) and dyaw[0] == pytest.approx(0.1)
    assert np.isnan(xy[1]) and np.isnan(dyaw[1])
    with pytest.raises(ValueError, match="must both be"):
        plots.localization_error(truth, est[:1])


@pytest.mark.parametrize("breakage, match", [
    (lambda d: (d / "trajectory.json").unlink(), "trajectory.json: no such file"),
    (lambda d: (d / "trajectory.json").write_text("{not json"), "trajectory.json: not valid JSON"),
    (lambda d: (d / "trajectory.json").write_text('{"samples": {}}'), "trajectory.json: missing or malformed"),
    (lambda d: (d / "trajectory.json").write_text(json.dumps(
        {"map_file": "x", "legs": [], "samples": {"t": [], "truth": [], "estimate": []}})), "no samples"),
    (lambda d: (d / "delivery.json").write_text('{"legs": 3}'), "delivery.json: field 'legs'"),
])
def test_bad_input_names_the_file(tmp_path: Path, breakage, match: str) -> None:
    d = _route(tmp_path)
    breakage(d)
    with pytest.raises(plots.PlotError, match=match):
        plots.write_plots(d)


def test_missing_map_file_is_named(tmp_path: Path) -> None:
    d = _route(tmp_path, map_file=tmp_path / "nowhere.yaml")
    with pytest.raises(plots.PlotError, match="nowhere.yaml"):
        plots.write_plots(d)
    assert plots.main([str(d)]) == 1
