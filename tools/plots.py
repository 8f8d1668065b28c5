#!/usr/bin/env python3
"""The delivery run's plots (PNG), from the JSON files `make demo` writes (pure: no ROS).

    python tools/plots.py [DIR]      # DIR (default build/demo) holds delivery.json + trajectory.json

Reads ``delivery.json`` (per leg: time, time-optimal limit ``limit_s``, outcome; tools/demo.py) and
``trajectory.json`` (5 Hz ground truth and localization estimate, each leg's goal and global plan,
the map file; tools/delivery.py :meth:`DeliveryClient.trajectory`) and writes into DIR:

* ``trajectory.png`` -- the map (map_server YAML + image, chefbot_common.map_io) with the
  ground-truth path, the localization estimate and every leg's plan; the tables' delivery
  poses marked and labelled;
* ``localization_error.png`` -- position (m) and heading (rad) error of the estimate against
  the ground truth over sim time, leg boundaries marked;
* ``leg_times.png`` -- per leg: delivery time next to the time-optimal limit and the 1.15x goal.

Drawn with matplotlib (Agg backend, no display needed).  Units: m, rad, s (sim time).
"""
from __future__ import annotations

import json
import math
import sys
from collections.abc import Sequence
from pathlib import Path

import numpy as np

RATIO_GOAL = 1.15           # a leg may take at most this times its time-optimal limit (end-to-end issue)
MAX_INTERP_GAP_S = 0.25     # s: a truth sample further than this from the asked stamp is not used
PLOT_NAMES = ("trajectory.png", "localization_error.png", "leg_times.png")
DPI = 110


class PlotError(ValueError):
    """The input of a plot is unusable; the message names the file and the field."""


# ---------------------------------------------------------------- pure helpers
def pose_at(history: Sequence[tuple[float, float, float, float]], t: float,
            max_gap: float = MAX_INTERP_GAP_S) -> tuple[float, float, float] | None:
    """(x, y, yaw) at time ``t`` from time-sorted samples (t s, x m, y m, yaw rad), linearly
    interpolated (yaw along the shorter arc); None when ``t`` lies more than ``max_gap`` s outside
    the samples or the samples are empty.  Outside the samples (within ``max_gap``) the nearest end."""
    if not history:
        return None
    ts = np.array([h[0] for h in history], dtype=float)
    if not math.isfinite(t) or t < ts[0] - max_gap or t > ts[-1] + max_gap:
        return None
    i = int(np.searchsorted(ts, t))
    if i <= 0 or i >= len(ts):
        h = history[0] if i <= 0 else history[-1]
        return float(h[1]), float(h[2]), float(h[3])
    a, b = history[i - 1], history[i]
    span = b[0] - a[0]
    if min(t - a[0], b[0] - t) > max_gap:   # inside a gap in the samples
        return None
    f = (t - a[0]) / span if span > 0 else 0.0
    dyaw = math.remainder(b[3] - a[3], 2 * math.pi)
    return (a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]),
            math.remainder(a[3] + f * dyaw, 2 * math.pi))


def localization_error(truth: np.ndarray, estimate: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Position error (m) and absolute heading error (rad, wrapped) of ``estimate`` against ``truth``,
    both (N, 3) [x, y, yaw]; NaN rows (no estimate) give NaN."""
    truth, estimate = np.asarray(truth, dtype=float), np.asarray(estimate, dtype=float)
    if truth.shape != estimate.shape or truth.ndim != 2 or truth.shape[1] != 3:
        raise ValueError(f"truth {truth.shape} and estimate {estimate.shape} must both be (N, 3)")
    xy = np.hypot(estimate[:, 0] - truth[:, 0], estimate[:, 1] - truth[:, 1])
    dyaw = np.abs(np.remainder(estimate[:, 2] - truth[:, 2] + np.pi, 2 * np.pi) - np.pi)
    return xy, dyaw


def _read_json(path: Path) -> dict:
    if not path.is_file():
        raise PlotError(f"{path}: no such file (run `make demo` first)")
    try:
        data = json.loads(path.read_text())
    except (json.JSONDecodeError, UnicodeDecodeError) as exc:
        raise PlotError(f"{path}: not valid JSON ({exc})") from exc
    if not isinstance(data, dict):
        raise PlotError(f"{path}: expected a JSON object at the top")
    return data


def load_trajectory(path: Path) -> dict:
    """``trajectory.json`` checked and as arrays: t (N,), truth (N, 3), estimate (N, 3; NaN = none)."""
    data = _read_json(path)
    try:
        s = data["samples"]
        t = np.asarray(s["t"], dtype=float).reshape(-1)
        truth = np.asarray(s["truth"], dtype=float).reshape(-1, 3)
        est = np.array([[np.nan] * 3 if e is None else e for e in s["estimate"]], dtype=float).reshape(-1, 3)
        legs = data["legs"]
        map_file = str(data["map_file"])
    except (KeyError, TypeError, ValueError) as exc:
        raise PlotError(f"{path}: missing or malformed field ({exc!r}); expected samples.t/truth/estimate, "
                        "legs, map_file") from exc
    if not (len(t) == len(truth) == len(est)):
        raise PlotError(f"{path}: samples.t, .truth and .estimate differ in length "
                        f"({len(t)}, {len(truth)}, {len(est)})")
    if len(t) == 0:
        raise PlotError(f"{path}: no samples (the route recorded nothing)")
    for i, leg in enumerate(legs):
        if not isinstance(leg, dict) or not {"name", "goal", "t_start", "t_end", "plan"} <= set(leg):
            raise PlotError(f"{path}: legs[{i}] needs name, goal, t_start, t_end, plan")
    return {"t": t, "truth": truth, "estimate": est, "legs": legs, "map_file": map_file,
            "estimate_source": data.get("estimate_source", "estimate")}


def load_delivery(path: Path) -> list[dict]:
    """The legs of ``delivery.json`` (name, ok, state, seconds, limit_s)."""
    data = _read_json(path)
    legs = data.get("legs")
    if not isinstance(legs, list):
        raise PlotError(f"{path}: field 'legs' missing or not a list")
    for i, leg in enumerate(legs):
        if not isinstance(leg, dict) or not {"name", "ok", "seconds", "limit_s"} <= set(leg):
            raise PlotError(f"{path}: legs[{i}] needs name, ok, seconds, limit_s")
    return legs


# ---------------------------------------------------------------- plots
def _pyplot():
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    return plt


def plot_trajectory(traj: dict, out: Path, map_file: Path | None = None) -> Path:
    """The map with the ground truth, the estimate and the plans overlaid; tables labelled."""
    from matplotlib import transforms

    from chefbot_common.map_io import MapError, load_map
    plt = _pyplot()
    map_path = Path(map_file or traj["map_file"])
    try:
        occ = load_map(map_path)
    except MapError as exc:
        raise PlotError(f"trajectory plot: {exc}") from exc
    info = occ.info
    shade = np.full(occ.data.shape, 0.82)            # unknown: light grey
    shade[occ.data == 0] = 1.0                       # free: white
    shade[occ.data >= 65] = 0.15                     # occupied (map_saver's threshold): near black
    fig, ax = plt.subplots(figsize=(9, 7), dpi=DPI)
    extent = (info.origin_x, info.origin_x + info.width * info.resolution,
              info.origin_y, info.origin_y + info.height * info.resolution)
    rot = transforms.Affine2D().rotate_around(info.origin_x, info.origin_y, info.origin_yaw)
    ax.imshow(shade, cmap="gray", vmin=0, vmax=1, origin="lower", extent=extent, interpolation="nearest",
              transform=rot + ax.transData)
    for i, leg in enumerate(traj["legs"]):
        plan = np.asarray(leg["plan"], dtype=float).reshape(-1, 2)
        if len(plan) > 1:
            ax.plot(plan[:, 0], plan[:, 1], color="tab:green", lw=1.2, alpha=0.8,
                    label="global plan (per leg)" if i == 0 else None)
    truth, est = traj["truth"], traj["estimate"]
    ax.plot(truth[:, 0], truth[:, 1], color="tab:blue", lw=1.8, label="ground truth (simulator)")
    ax.plot(est[:, 0], est[:, 1], color="tab:orange", lw=1.2, ls="--",
            label=f"localization estimate: {traj['estimate_source']}")
    # every leg's goal (table delivery poses and home) once, with its heading
    goals: dict[str, list[float]] = {leg["name"]: leg["goal"] for leg in traj["legs"]}
    for name, (gx, gy, gyaw) in goals.items():
        home = name == "home"
        ax.plot(gx, gy, marker="s" if home else "o", ms=7, color="tab:red" if home else "tab:purple",
                mec="black", zorder=5)
        ax.annotate("", xy=(gx + 0.35 * math.cos(gyaw), gy + 0.35 * math.sin(gyaw)), xytext=(gx, gy),
                    arrowprops={"arrowstyle": "->", "color": "black", "lw": 1}, zorder=5)
        ax.annotate(name.replace("table_", "T"), (gx, gy), xytext=(-4, 7), textcoords="offset points",
                    ha="right", fontsize=9, fontweight="bold",
                    bbox={"boxstyle": "round,pad=0.15", "fc": "white", "ec": "none", "alpha": 0.8}, zorder=6)
    # show the known part of the map and the route, not the map's unknown margin
    known_r, known_c = np.nonzero(occ.data >= 0)
    pts = [truth[:, :2], est[np.isfinite(est[:, 0]), :2], np.array([g[:2] for g in goals.values()]).reshape(-1, 2)]
    if len(known_r):
        corners = [info.grid_to_world(c, r) for c in (known_c.min(), known_c.max() + 1)
                   for r in (known_r.min(), known_r.max() + 1)]
        pts.append(np.array(corners))
    allp = np.vstack([p for p in pts if len(p)])
    lo, hi = allp.min(axis=0) - 0.5, allp.max(axis=0) + 0.5
    ax.set_xlim(lo[0], hi[0])
    ax.set_ylim(lo[1], hi[1])
    ax.set_aspect("equal")
    ax.set_xlabel("x (m, map frame)")
    ax.set_ylabel("y (m, map frame)")
    ax.set_title(f"Delivery route on {map_path.name}: {len(traj['legs'])} legs, "
                 f"{traj['t'][-1] - traj['t'][0]:.0f} s sim time")
    ax.grid(True, color="0.6", lw=0.4, alpha=0.5)
    ax.legend(loc="upper left", bbox_to_anchor=(0.0, -0.09), ncol=2, fontsize=8, frameon=False)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def _leg_bounds(ax, legs: list[dict], t0: float, label: bool) -> None:
    for leg in legs:
        ax.axvline(leg["t_start"] - t0, color="0.5", lw=0.7, ls=":")
        if label:
            mid = 0.5 * (leg["t_start"] + leg["t_end"]) - t0
            ax.text(mid, 1.01, leg["name"].replace("table_", "T"), transform=ax.get_xaxis_transform(),
                    ha="center", va="bottom", fontsize=8)


def plot_localization_error(traj: dict, out: Path) -> Path:
    """Position and heading error of the estimate over sim time, leg boundaries dotted."""
    plt = _pyplot()
    t0 = float(traj["t"][0])
    t = traj["t"] - t0
    xy, dyaw = localization_error(traj["truth"], traj["estimate"])
    fig, (a1, a2) = plt.subplots(2, 1, figsize=(10, 5.5), dpi=DPI, sharex=True)
    for ax, err, unit, color in ((a1, xy, "m", "tab:blue"), (a2, dyaw, "rad", "tab:red")):
        ax.plot(t, err, color=color, lw=1.0)
        ok = np.isfinite(err)
        if ok.any():
            rms, peak = float(np.sqrt(np.mean(err[ok] ** 2))), float(np.max(err[ok]))
            ax.axhline(rms, color=color, lw=0.8, ls="--", alpha=0.7)
            ax.text(0.995, 0.95, f"RMS {rms:.3f} {unit}, max {peak:.3f} {unit}", transform=ax.transAxes,
                    ha="right", va="top", fontsize=9,
                    bbox={"boxstyle": "round,pad=0.2", "fc": "white", "ec": "0.7"})
        ax.set_ylim(0, 1.25 * float(np.max(err[ok])) if ok.any() and np.max(err[ok]) > 0 else 1.0)
        ax.grid(True, lw=0.4, alpha=0.5)
        _leg_bounds(ax, traj["legs"], t0, label=ax is a1)
    a1.set_ylabel("position error (m)")
    a2.set_ylabel("heading error (rad)")
    a2.set_xlabel("sim time since the first sample (s)")
    fig.suptitle(f"Localization error against the ground truth (estimate: {traj['estimate_source']})", fontsize=11)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def plot_leg_times(legs: list[dict], out: Path) -> Path:
    """Per leg: the delivery time next to its time-optimal limit; the 1.15x goal as a tick."""
    plt = _pyplot()
    if not legs:
        raise PlotError("leg times plot: no legs")
    names = [leg["name"].replace("table_", "T") for leg in legs]
    secs = np.array([leg["seconds"] if leg["seconds"] is not None else np.nan for leg in legs], dtype=float)
    lims = np.array([leg["limit_s"] if leg["limit_s"] is not None else np.nan for leg in legs], dtype=float)
    x = np.arange(len(legs))
    w = 0.38
    fig, ax = plt.subplots(figsize=(max(8.0, 0.8 * len(legs) + 2), 4.5), dpi=DPI)
    ax.bar(x - w / 2, np.nan_to_num(lims), w, color="0.7", label="time-optimal limit along the plan")
    colors = ["tab:blue" if leg["ok"] else "tab:red" for leg in legs]
    ax.bar(x + w / 2, np.nan_to_num(secs), w, color=colors, label="delivery time (red: not delivered)")
    ax.hlines(RATIO_GOAL * lims, x - w, x + w, colors="black", lw=1.2, label=f"goal: {RATIO_GOAL} x limit")
    top = np.nanmax(np.concatenate([secs, lims * RATIO_GOAL, [1.0]]))
    for xi, s, lim, leg in zip(x, secs, lims, legs, strict=True):
        if not leg["ok"]:
            text = leg.get("state", "FAILED")
        elif math.isfinite(lim) and lim > 0 and math.isfinite(s):
            text = f"{s / lim:.2f}x"
        else:
            text = "no plan"
        ax.text(xi + w / 2, max(s if math.isfinite(s) else 0, RATIO_GOAL * lim if math.isfinite(lim) else 0)
                + 0.015 * top, text, ha="center", va="bottom", fontsize=8, rotation=90 if len(text) > 6 else 0)
        if not math.isfinite(lim):
            ax.text(xi - w / 2, 0.015 * top, "no plan", ha="center", va="bottom", fontsize=8, rotation=90)
    ax.set_xticks(x, names)
    ax.set_ylim(0, top * 1.45)
    ax.set_ylabel("sim time (s)")
    ax.set_title("Per-leg delivery time vs the time-optimal limit (ratio time / limit on top)")
    ax.grid(True, axis="y", lw=0.4, alpha=0.5)
    ax.legend(fontsize=8, loc="upper center", ncol=3, frameon=False)
    fig.tight_layout()
    fig.savefig(out)
    plt.close(fig)
    return out


def write_plots(directory: Path, map_file: Path | None = None) -> list[Path]:
    """All three PNGs into ``directory`` from its delivery.json and trajectory.json; their paths.

    ``map_file`` overrides the map named in trajectory.json.  Raises :class:`PlotError`.
    """
    directory = Path(directory)
    traj = load_trajectory(directory / "trajectory.json")
    legs = load_delivery(directory / "delivery.json")
    return [plot_trajectory(traj, directory / PLOT_NAMES[0], map_file),
            plot_localization_error(traj, directory / PLOT_NAMES[1]),
            plot_leg_times(legs, directory / PLOT_NAMES[2])]


def main(argv: list[str]) -> int:
    directory = Path(argv[0]) if argv else Path(__file__).resolve().parent.parent / "build" / "demo"
    try:
        paths = write_plots(directory)
    except PlotError as exc:
        print(f"[plots] ERROR: {exc}", file=sys.stderr)
        return 1
    for p in paths:
        print(f"[plots] {p}")
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
