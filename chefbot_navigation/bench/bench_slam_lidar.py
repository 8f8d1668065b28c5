#!/usr/bin/env python3
"""SLAM benchmark on 2-D lidar drives: issue 30's hard-case variants in the hotel and in a long corridor.

Inputs: routes driven in the pybullet simulator without ROS (lidar_routes.py): the hotel (58 m round the
tables and back through the middle aisles) and ``worlds/corridor.yaml`` (22 m of corridor between two
rooms, there and back, a lap round a table in each room: 70 m), with a 180 deg / 180-beam lidar (the real
logs' kind; ``--lidars 360`` adds a 360 deg / 360-beam one), 10 Hz, 12 m, 0.01 m range noise; each route
driven smoothly (move_base's accelerations) and carelessly (``DRIVES``: no acceleration limits, the
wheels slipping in the turns); the simulator's wheel odometry (the noisy wheel model of
chefbot_sim/param/sim.yaml) and ground truth at every scan; simulator seed 0.  The recordings are made
at the start of a run (``--cache DIR`` keeps them).

Each scan goes to the SLAM core (``chefbot_navigation.slam.mapper.Slam``) as ``ros_slam_bag.run_bag``
gives it: the scan filter sees the recorded odometry, the odometry filter the kept scans in order, the
ranges become a ``Scan`` with the laser frame's pose in base_footprint from the robot model, no IMU,
no bumper, then ``Slam.refine()``.

Variants (bench_slam's, issue 30): every scan / one per 0.7 m or 25 deg / one per 1.1 m or 35 deg of
recorded odometry (``Decimate``) x the recorded odometry / a miscalibrated one (3 % distance, 2 % turn,
1.5 deg/m heading drift: ``OdometryNoise.miscalibrated()``) / that plus random noise (seeds 1-5): 21
per site and lidar.  Each runs with ``SlamConfig()`` (ours) and with
``SlamConfig(odometry_calibration=False)`` (the reference, "before"); the odometry bias the SLAM
learned goes to stderr.  ``--quick``: three variants (dense recorded, 0.7 m miscalibrated, 1.1 m
miscalibrated + noise seed 1).

ATE: position error of every scan given to the SLAM after the best rigid fit of the whole trajectory
to the truth (``metrics.aligned_errors``), RMS and max.  Goals (issue 30): on every variant ATE <= 0.10 m
RMS and <= 0.30 m max.

    python chefbot_navigation/bench/bench_slam_lidar.py [--quick] [--sites hotel corridor] [--lidars 180 360]
        [--drives smooth careless] [-k SUBSTRING] [--cache DIR] [--json FILE] [--profile]
"""
from __future__ import annotations

import argparse
import json
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE.parents[1] / "chefbot_navigation" / "src"))
sys.path.insert(0, str(HERE))

from bench_slam import (  # noqa: E402
    DECIMATIONS,
    VARIANT_ATE,
    VARIANT_ATE_MAX,
    calibration_off,
    learned_bias,
    variant_filters,
    variants,
)
from lidar_routes import LIDARS, SITES, Recording, record  # noqa: E402

from chefbot_common.geometry import Pose2D  # noqa: E402
from chefbot_navigation.slam.mapper import Slam, SlamConfig  # noqa: E402
from chefbot_navigation.slam.metrics import aligned_errors  # noqa: E402
from chefbot_navigation.slam.scan import ScanError, scan_from_ranges  # noqa: E402

SEED = 0             # the simulator's noise seed of the recordings
#: drive -> careless (lidar_routes.record): 'smooth' at move_base's accelerations; 'careless' without limits, the
#: wheels slipping in the turns (the wheel odometry counts 7-9 deg of a corner for 1-2 deg turned)
DRIVES = {"smooth": False, "careless": True}


def run_slam(rec: Recording, cfg: SlamConfig, odom_filter: Callable[[float, Pose2D], Pose2D] | None = None,
             scan_filter: Callable[[float, Pose2D], bool] | None = None) -> dict:
    """The SLAM over a recording, fed as ``run_bag`` feeds it (see the module docstring); ATE RMS / max (m) over
    the scans given, the per-scan errors and where they were (``index`` into the recording), wall time (s)."""
    slam = Slam(cfg)
    inc = float(rec.angles[1] - rec.angles[0])
    used: list[int] = []
    skipped = decimated = 0
    t0 = time.monotonic()
    for k, t in enumerate(rec.t.tolist()):
        raw = Pose2D(*map(float, rec.odom[k]))
        if scan_filter is not None and not scan_filter(t, raw):
            decimated += 1
            continue
        odom = odom_filter(t, raw) if odom_filter is not None else raw
        try:
            scan = scan_from_ranges(rec.ranges[k].astype(float), float(rec.angles[0]), inc, rec.range_min,
                                    rec.range_max, rec.laser, max_usable_range=min(cfg.maxUrange, rec.range_max),
                                    max_range=cfg.maxRange or None)
        except ScanError:
            skipped += 1
            continue
        slam.add_scan(t, scan, odom)
        used.append(k)
    if used:
        slam.refine()       # cfg.refine_passes final passes (0: none), as run_bag
    wall = time.monotonic() - t0
    est = np.array([(p.x, p.y) for _, p in slam.trajectory()])
    err = aligned_errors(est, rec.truth[used, :2])
    return {"slam": slam, "stats": slam.stats, "ate": float(np.sqrt(np.mean(err ** 2))), "ate_max": float(err.max()),
            "errors": err, "index": np.array(used), "scans": len(used), "skipped": skipped, "decimated": decimated,
            "wall_s": wall}


def lidar_variants(quick: bool) -> list[tuple[str, tuple[float, float] | None, str, int | None]]:
    """bench_slam's variants; quick: dense recorded, 0.7 m miscalibrated, 1.1 m miscalibrated + noise seed 1."""
    if not quick:
        return variants(False)
    return [("dense", None, "recorded odometry", None), (*DECIMATIONS[1], "miscalibrated odometry", 0),
            (*DECIMATIONS[2], "miscalibrated odometry + noise seed 1", 1)]


def recording(site: str, lidar: str, cache: Path | None = None, drive: str = "smooth") -> Recording:
    """The site's drive (``DRIVES``) with the lidar (from ``cache`` if it holds it; then saved there)."""
    path = cache / f"{site}_lidar{lidar}_{drive}_seed{SEED}.npz" if cache is not None else None
    if path is not None and path.is_file():
        return Recording.load(path)
    rec = record(site, lidar, SEED, careless=DRIVES[drive])
    if path is not None:
        path.parent.mkdir(parents=True, exist_ok=True)
        rec.save(path)
    return rec


def where(rec: Recording, res: dict) -> dict:
    """Where along the route the error is: the worst scan's leg, distance driven (m) and true x, y; the max error
    per leg (m)."""
    idx = res["index"]
    step = np.hypot(*np.diff(rec.truth[:, :2], axis=0).T)
    dist = np.concatenate(([0.0], np.cumsum(step)))
    worst = int(np.argmax(res["errors"]))
    k = idx[worst]
    legs = rec.leg[idx]
    per_leg = {int(g): round(float(res["errors"][legs == g].max()), 3) for g in np.unique(legs)}
    return {"worst_leg": int(rec.leg[k]), "worst_at_m": round(float(dist[k]), 1),
            "worst_xy": (round(float(rec.truth[k, 0]), 2), round(float(rec.truth[k, 1]), 2)), "max_per_leg": per_leg}


def _row(case: str, metric: str, ours: float, goal: str | None, met: bool | None, reference: float | None = None,
         reference_name: str | None = None, **detail) -> dict:
    row = {"bench": "slam_lidar", "case": case, "metric": metric, "ours": round(float(ours), 4),
           "reference": reference, "reference_name": reference_name, "goal": goal, "met": met}
    if detail:
        row["detail"] = detail
    return row


def run(quick: bool = False, sites: tuple[str, ...] = tuple(SITES), lidars: tuple[str, ...] = ("180",),
        pattern: str | None = None, cache: Path | None = None, drives: tuple[str, ...] = tuple(DRIVES)) -> list[dict]:
    """Benchmark rows (see tools/bench.py); ``pattern``: only the variants whose name holds it."""
    rows: list[dict] = []
    ref_name = "without odometry calibration"
    for site, lidar, drive in ((s, li, d) for s in sites for li in lidars for d in drives):
        rec = recording(site, lidar, cache, drive)
        lid = LIDARS[lidar]
        head = f"{site} {rec.length:.0f} m, {drive} drive, lidar {lid.fov:.0f} deg / {lid.beams} beams"
        rows.append(_row(f"{head}: recording ({rec.t[-1]:.0f} s sim, {len(rec.t)} scans)",
                         "recording wall time (s)", rec.wall_s, None, None))
        for dec_name, dec, odo_name, noise in lidar_variants(quick):
            name = f"{dec_name}, {odo_name}"
            if pattern and pattern not in name:
                continue
            ours = run_slam(rec, SlamConfig(), **variant_filters(dec, noise))
            before = run_slam(rec, calibration_off(), **variant_filters(dec, noise))
            case = f"{head}, variant: {name}"
            bias = learned_bias(ours["stats"])
            info = {"learned": bias, "loops": ours["stats"].loop_closures,
                    "loops_before": before["stats"].loop_closures, "where": where(rec, ours),
                    "where_before": where(rec, before), "slam_wall_s": round(ours["wall_s"] + before["wall_s"], 1)}
            rows.append(_row(case, "ATE RMS (m)", ours["ate"], f"<= {VARIANT_ATE:.2f}", ours["ate"] <= VARIANT_ATE,
                             round(before["ate"], 4), ref_name, **info))
            rows.append(_row(case, "ATE max (m)", ours["ate_max"], f"<= {VARIANT_ATE_MAX:.2f}",
                             ours["ate_max"] <= VARIANT_ATE_MAX, round(before["ate_max"], 4), ref_name))
            if noise is None:
                rows.append(_row(case, "scans used", ours["scans"], None, None))
            print(f"{case}: learned odometry {bias}; SLAM {ours['wall_s']:.0f} + {before['wall_s']:.0f} s wall",
                  file=sys.stderr, flush=True)
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--sites", nargs="+", choices=tuple(SITES), default=list(SITES))
    ap.add_argument("--lidars", nargs="+", choices=tuple(LIDARS), default=["180"], help="default: 180")
    ap.add_argument("--drives", nargs="+", choices=tuple(DRIVES), default=list(DRIVES))
    ap.add_argument("-k", dest="pattern", help="only the variants whose name holds this, e.g. '0.7 m' or 'seed 3'")
    ap.add_argument("--cache", type=Path, help="directory to keep the recordings in (read when there)")
    ap.add_argument("--json", type=Path, help="write the rows (with where along the route the error is) here")
    ap.add_argument("--profile", action="store_true", help="print the max error per route leg of each variant")
    a = ap.parse_args()
    rows = run(a.quick, tuple(a.sites), tuple(a.lidars), a.pattern, a.cache, tuple(a.drives))
    for r in rows:
        ref = "-" if r["reference"] is None else f"{r['reference']:.3f}"
        print(f"{r['case']:<100} {r['metric']:<24} {r['ours']:>9} before {ref:>7} goal {r['goal'] or '-':<7} "
              f"met {r['met']}")
        d = r.get("detail")
        if d:
            print(f"    learned {d['learned']}; loop closures {d['loops']} (before {d['loops_before']}); worst at "
                  f"{d['where']['worst_at_m']} m {d['where']['worst_xy']} leg {d['where']['worst_leg']}; "
                  f"SLAM {d['slam_wall_s']} s wall")
            if a.profile:
                print(f"    max per leg: {d['where']['max_per_leg']}\n"
                      f"    before:      {d['where_before']['max_per_leg']}")
    if a.json:
        a.json.write_text(json.dumps(rows, indent=1) + "\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
