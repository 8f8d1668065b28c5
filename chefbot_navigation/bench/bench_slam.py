#!/usr/bin/env python3
"""SLAM benchmark: offline speed, map quality and trajectory error on a recorded hotel run.

Input: ``chefbot_navigation/test/fixtures/hotel_route.bag`` (2.9 MB), recorded
from the pybullet hotel (plugin drive, wheel odometry from the simulated wheel
joints: it slips in spins) while move_base drove a fixed route round the room
with look-around spins; /scan (the ~58 deg depth-camera band), odom tf, and
ground truth (10 Hz) for scoring.  The ground-truth map is the world raster
(chefbot_sim raster.py via hotel_world_map.yaml).  The robot starts at the world
origin, so the SLAM map frame (odom at the first scan) is the world frame.

Noise switch: ``noise=True`` multiplies the recorded odometry's error with an
extra wheel model (OdometryNoise: 2 % scale bias, 5 % rotation bias, random
per-scan errors, 0.02 rad/m heading drift) - the bench reports both, the noise with three seeds.

    python chefbot_navigation/bench/bench_slam.py [--quick] [--bag BAG]

Goals (issue): matched >= 95 %, false-occupied <= 2 %, ATE <= 0.05 m RMS,
offline >= 5x real time.  References: ATE of GMapping 0.07 m and graph SLAM
0.03 m on the Intel Research Lab data (Kuemmerle et al. 2009).
"""
from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "src"))

from chefbot_common.map_io import load_map  # noqa: E402
from chefbot_navigation.ros_slam_bag import run_bag  # noqa: E402
from chefbot_navigation.slam.mapper import SlamConfig  # noqa: E402
from chefbot_navigation.slam.metrics import ate_rms, map_quality  # noqa: E402
from chefbot_navigation.slam.synthetic import OdometryNoise  # noqa: E402

BAG = ROOT / "chefbot_navigation" / "test" / "fixtures" / "hotel_route.bag"
TRUTH_MAP = ROOT / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"


def ground_truth(bag_path: Path) -> np.ndarray:
    """(N, 3) t, x, y of ground_truth/odom in the bag."""
    import rosbag
    with rosbag.Bag(str(bag_path)) as bag:
        return np.array([(m.header.stamp.to_sec(), m.pose.pose.position.x, m.pose.pose.position.y)
                         for _, m, _ in bag.read_messages(topics=["/ground_truth/odom"])])


def evaluate(bag_path: Path, cfg: SlamConfig, noise: bool, seed: int = 1) -> dict:
    """Run the offline SLAM on the bag; speed, map quality, ATE."""
    res = run_bag(bag_path, cfg, odom_filter=OdometryNoise(seed=seed) if noise else None)
    slam = res.front.slam
    gt = ground_truth(bag_path)
    traj = slam.trajectory()
    t = np.array([s for s, _ in traj])
    est = np.array([(p.x, p.y) for _, p in traj])
    truth = np.column_stack((np.interp(t, gt[:, 0], gt[:, 1]), np.interp(t, gt[:, 0], gt[:, 2])))
    q = map_quality(slam.occupancy(), load_map(TRUTH_MAP))
    return {"speedup": res.speedup, "matched": 100 * q.matched, "false": 100 * q.false_occupied,
            "coverage": 100 * q.coverage, "ate": ate_rms(est, truth), "loops": slam.stats.loop_closures}


def _row(case: str, metric: str, ours: float, goal: str | None, met: bool | None, reference: float | None = None,
         reference_name: str | None = None) -> dict:
    return {"bench": "slam", "case": case, "metric": metric, "ours": round(float(ours), 4),
            "reference": reference, "reference_name": reference_name, "goal": goal, "met": met}


def run(quick: bool = False, bag: Path = BAG) -> list[dict]:
    """Benchmark rows (see tools/bench.py)."""
    rows: list[dict] = []
    # the extra noise is random: three seeds (one can be lucky or unlucky: seed 1 of the 2026-11-24
    # bench was the best of the three with turn calibration off and the worst with it on)
    variants = [("recorded odometry", False, 1)]
    if not quick:
        variants += [(f"extra wheel noise seed {seed}", True, seed) for seed in (1, 2, 3)]
    for name, noise, seed in variants:
        sm = evaluate(bag, SlamConfig(), noise, seed)
        case = f"hotel route 325 s, {name}"
        rows.append(_row(case, "offline speed (x real time)", sm["speedup"], ">= 5", sm["speedup"] >= 5))
        rows.append(_row(case, "GT occupied matched within 1 cell (%)", sm["matched"], ">= 95", sm["matched"] >= 95))
        rows.append(_row(case, "false occupied (%)", sm["false"], "<= 2", sm["false"] <= 2))
        rows.append(_row(case, "reachable free area mapped (%)", sm["coverage"], None, None))
        rows.append(_row(case, "ATE RMS (m)", sm["ate"], "<= 0.05", sm["ate"] <= 0.05, 0.07,
                         "GMapping, Intel lab (Kuemmerle 2009)"))
        rows.append(_row(case, "loop closures", sm["loops"], None, None))
        if seed != 1:
            continue        # the comparisons: once per odometry
        raw = evaluate(bag, SlamConfig(scan_matching=False, loop_closure=False), noise)
        case_raw = f"{case}, scan matching OFF"
        rows.append(_row(case_raw, "GT occupied matched within 1 cell (%)", raw["matched"], None, None))
        rows.append(_row(case_raw, "false occupied (%)", raw["false"], None, None))
        rows.append(_row(case_raw, "ATE RMS (m)", raw["ate"], None, None))
        if not quick:
            nl = evaluate(bag, SlamConfig(loop_closure=False), noise)
            case_nl = f"{case}, loop closure OFF"
            rows.append(_row(case_nl, "GT occupied matched within 1 cell (%)", nl["matched"], None, None))
            rows.append(_row(case_nl, "false occupied (%)", nl["false"], None, None))
            rows.append(_row(case_nl, "ATE RMS (m)", nl["ate"], None, None))
    return rows


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--quick", action="store_true")
    ap.add_argument("--bag", type=Path, default=BAG, help="bag with scan, tf, ground_truth/odom (robot from 0,0,0)")
    a = ap.parse_args()
    for r in run(a.quick, a.bag):
        print(f"{r['case']:<60} {r['metric']:<40} {r['ours']:>10} goal {r['goal'] or '-':<8} met {r['met']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
