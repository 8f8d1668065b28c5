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

Hard-case variants (issue 30): the same bag with its scans thinned to one per
0.7 m / 25 deg and one per 1.1 m / 35 deg of recorded odometry (``Decimate``),
each with the recorded odometry, with a miscalibrated one (3 % distance, 2 %
turn, 1.5 deg/m heading drift: ``OdometryNoise.miscalibrated()``) and with that
plus random noise (seeds 1-5); ATE RMS and max per variant, next to the same run
with ``SlamConfig(odometry_calibration=False)`` as the reference.  ``--quick`` keeps the
dense recorded one and one thinned miscalibrated one.

    python chefbot_navigation/bench/bench_slam.py [--quick] [--bag BAG]

Goals (issue): matched >= 95 %, false-occupied <= 2 %, ATE <= 0.05 m RMS,
offline >= 5x real time; on every hard-case variant ATE <= 0.10 m RMS and
<= 0.30 m max.  References: ATE of GMapping 0.07 m and graph SLAM 0.03 m on the
Intel Research Lab data (Kuemmerle et al. 2009).
"""
from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "src"))

from chefbot_common.map_io import load_map  # noqa: E402
from chefbot_navigation.ros_slam_bag import run_bag  # noqa: E402
from chefbot_navigation.slam.mapper import SlamConfig  # noqa: E402
from chefbot_navigation.slam.metrics import aligned_errors, map_quality  # noqa: E402
from chefbot_navigation.slam.synthetic import Decimate, OdometryNoise  # noqa: E402

BAG = ROOT / "chefbot_navigation" / "test" / "fixtures" / "hotel_route.bag"
TRUTH_MAP = ROOT / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"

# hard-case variants (issue 30): (name, (min m, min deg) between kept scans or None: every scan)
DECIMATIONS = (("dense", None), ("one scan per 0.7 m / 25 deg", (0.7, 25.0)),
               ("one scan per 1.1 m / 35 deg", (1.1, 35.0)))
NOISE_SEEDS = (1, 2, 3, 4, 5)
VARIANT_ATE, VARIANT_ATE_MAX = 0.10, 0.30      # m, the goals on every variant


def ground_truth(bag_path: Path) -> np.ndarray:
    """(N, 3) t, x, y of ground_truth/odom in the bag."""
    import rosbag
    with rosbag.Bag(str(bag_path)) as bag:
        return np.array([(m.header.stamp.to_sec(), m.pose.pose.position.x, m.pose.pose.position.y)
                         for _, m, _ in bag.read_messages(topics=["/ground_truth/odom"])])


def trajectory_error(bag_path: Path, cfg: SlamConfig, odom_filter: Callable | None = None,
                     scan_filter: Callable | None = None) -> dict:
    """Run the offline SLAM on the bag (``run_bag``'s filters); ATE RMS and max (m) over the scans given."""
    res = run_bag(bag_path, cfg, odom_filter=odom_filter, scan_filter=scan_filter)
    slam = res.front.slam
    gt = ground_truth(bag_path)
    traj = slam.trajectory()
    t = np.array([s for s, _ in traj])
    est = np.array([(p.x, p.y) for _, p in traj])
    truth = np.column_stack((np.interp(t, gt[:, 0], gt[:, 1]), np.interp(t, gt[:, 0], gt[:, 2])))
    err = aligned_errors(est, truth)
    return {"result": res, "slam": slam, "ate": float(np.sqrt(np.mean(err ** 2))), "ate_max": float(err.max()),
            "scans": res.scans, "decimated": res.decimated}


def evaluate(bag_path: Path, cfg: SlamConfig, noise: bool, seed: int = 1) -> dict:
    """Run the offline SLAM on the bag; speed, map quality, ATE."""
    te = trajectory_error(bag_path, cfg, odom_filter=OdometryNoise(seed=seed) if noise else None)
    slam = te["slam"]
    q = map_quality(slam.occupancy(), load_map(TRUTH_MAP))
    return {"speedup": te["result"].speedup, "matched": 100 * q.matched, "false": 100 * q.false_occupied,
            "coverage": 100 * q.coverage, "ate": te["ate"], "ate_max": te["ate_max"],
            "loops": slam.stats.loop_closures, "stats": slam.stats, "scans": te["scans"]}


def calibration_off() -> SlamConfig:
    """The reference configuration of the variants: the odometry calibration off."""
    return SlamConfig(odometry_calibration=False)


def learned_bias(stats) -> str:
    """The odometry bias the SLAM learned (the fields it has; 1 / 0: nothing learned)."""
    drift = getattr(stats, "drift_per_m", None)
    return (f"distance x{getattr(stats, 'distance_scale', 1.0):.4f}, turn x{getattr(stats, 'turn_scale', 1.0):.4f}"
            + (f", drift {math.degrees(drift):+.2f} deg/m" if drift is not None else ", drift not learned"))


def variants(quick: bool) -> list[tuple[str, tuple[float, float] | None, str, int | None]]:
    """(decimation name, (m, deg) or None, odometry name, noise: None recorded / 0 miscalibrated / seed k)."""
    if quick:
        return [("dense", None, "recorded odometry", None),
                (*DECIMATIONS[1], "miscalibrated odometry", 0)]
    odometries = [("recorded odometry", None), ("miscalibrated odometry", 0)]
    odometries += [(f"miscalibrated odometry + noise seed {k}", k) for k in NOISE_SEEDS]
    return [(dn, dec, on, noise) for dn, dec in DECIMATIONS for on, noise in odometries]


def variant_filters(dec: tuple[float, float] | None, noise: int | None) -> dict:
    """Fresh (stateful) ``run_bag`` filters of a variant (see :func:`variants`)."""
    return {"odom_filter": None if noise is None else OdometryNoise.miscalibrated(seed=noise or None),
            "scan_filter": None if dec is None else Decimate(dec[0], math.radians(dec[1]))}


def variant_rows(bag: Path, quick: bool, dense_recorded: dict | None = None) -> list[dict]:
    """ATE RMS / max of each hard-case variant, the run without odometry calibration as the reference.
    ``dense_recorded``: the main rows' run of today's configuration on the recorded odometry, reused."""
    rows: list[dict] = []
    before_cfg = calibration_off()
    ref_name = "without odometry calibration"
    for dec_name, dec, odo_name, noise in variants(quick):
        if dec is None and noise is None and dense_recorded is not None:
            ours = dense_recorded
        else:
            ours = trajectory_error(bag, SlamConfig(), **variant_filters(dec, noise))
            ours["stats"] = ours["slam"].stats
        before = trajectory_error(bag, before_cfg, **variant_filters(dec, noise))
        case = f"hotel route variant: {dec_name}, {odo_name}"
        rows.append(_row(case, "ATE RMS (m)", ours["ate"], f"<= {VARIANT_ATE:.2f}", ours["ate"] <= VARIANT_ATE,
                         round(float(before["ate"]), 4), ref_name))
        rows.append(_row(case, "ATE max (m)", ours["ate_max"], f"<= {VARIANT_ATE_MAX:.2f}",
                         ours["ate_max"] <= VARIANT_ATE_MAX, round(float(before["ate_max"]), 4), ref_name))
        if noise is None:
            rows.append(_row(case, "scans used", ours["scans"], None, None))
        print(f"{case}: learned odometry {learned_bias(ours['stats'])}", file=sys.stderr)
    return rows


def _row(case: str, metric: str, ours: float, goal: str | None, met: bool | None, reference: float | None = None,
         reference_name: str | None = None) -> dict:
    return {"bench": "slam", "case": case, "metric": metric, "ours": round(float(ours), 4),
            "reference": reference, "reference_name": reference_name, "goal": goal, "met": met}


def run(quick: bool = False, bag: Path = BAG) -> list[dict]:
    """Benchmark rows (see tools/bench.py)."""
    rows: list[dict] = []
    # the extra noise is random: three seeds (one can be lucky or unlucky: seed 1 of the 2026-11-24
    # bench was the best of the three with turn calibration off and the worst with it on)
    cases = [("recorded odometry", False, 1)]
    if not quick:
        cases += [(f"extra wheel noise seed {seed}", True, seed) for seed in (1, 2, 3)]
    dense_recorded = None
    for name, noise, seed in cases:
        sm = evaluate(bag, SlamConfig(), noise, seed)
        if not noise:
            dense_recorded = sm
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
    rows += variant_rows(bag, quick, dense_recorded)
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
