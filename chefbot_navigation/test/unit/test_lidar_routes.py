"""The lidar route recorder of the SLAM benchmark (bench/lidar_routes.py, issue 30) and its corridor world."""
from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[3]
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "bench"))

from lidar_routes import LIDARS, SITES, Recording, record  # noqa: E402

from chefbot_sim.world import load_world  # noqa: E402


def test_corridor_world_loads_and_the_routes_are_clear():
    xmin, _, xmax, _ = load_world(ROOT / "chefbot_sim" / "worlds" / "corridor.yaml").bounds_xy()
    assert xmax - xmin >= 30.0
    for name, site in SITES.items():
        w = load_world(ROOT / "chefbot_sim" / "worlds" / site.world)
        route = [(site.start.x, site.start.y), *site.route]
        assert route[-1] == route[0], name                              # back where it started
        for (x0, y0), (x1, y1) in zip(route[:-1], route[1:], strict=True):
            for f in np.linspace(0.0, 1.0, 50):                          # room for the 0.18 m robot
                assert w.clearance(x0 + f * (x1 - x0), y0 + f * (y1 - y0)) >= 0.3, (name, x0, y0, x1, y1, f)


def test_recorder_on_a_short_corridor_route(tmp_path: Path):
    rec = record("corridor", "180", seed=1, route=((1.0, 0.0), (1.0, 0.5)))
    n = len(rec.t)
    assert n >= 30 and np.all(np.diff(rec.t) > 0)
    assert rec.ranges.shape == (n, LIDARS["180"].beams) and rec.angles.shape == (LIDARS["180"].beams,)
    assert np.all(np.isfinite(rec.truth)) and np.all(np.isfinite(rec.odom))
    assert np.isfinite(rec.ranges).mean() > 0.9                  # walls all round within 12 m
    assert np.hypot(rec.truth[-1, 0] - 1.0, rec.truth[-1, 1] - 0.5) < 0.05
    assert set(rec.leg.tolist()) == {0, 1}
    assert np.abs(rec.odom[-1, :2] - rec.truth[-1, :2]).max() < 0.1     # noisy, but wheel odometry
    again = record("corridor", "180", seed=1, route=((1.0, 0.0), (1.0, 0.5)))
    assert np.array_equal(again.ranges, rec.ranges) and np.array_equal(again.odom, rec.odom)   # deterministic
    rec.save(tmp_path / "r.npz")
    back = Recording.load(tmp_path / "r.npz")
    assert np.array_equal(back.ranges, rec.ranges) and back.laser == rec.laser and back.site == "corridor"
