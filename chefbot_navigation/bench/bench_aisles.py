#!/usr/bin/env python3
"""Narrow aisles benchmark (pure, no ROS): move_base's Navigator with the URDF footprint on a perfect
unicycle (test/unicycle_nav.py).

* the cafe test site (chefbot_navigation/maps/cafe_*.yaml, aisles 0.50-0.90 m): every table and
  home; per leg the time against the time-optimal limit (chefbot_navigation.time_limit.simple_limit:
  length / v_max + turns / w_max, goal <= 1.5x) and contacts of the collision bodies with the map;
* single passages 0.30-0.45 m wide: the smallest one taken, and for narrower ones the time from the
  first "blocked" report to the abort with the reason (goal <= 10 s);
* generated dead ends (unicycle_nav.random_dead_end: an aisle 0.40-0.52 m wide, too narrow to turn
  in, ending in a 0.34-0.37 m gap, at any angle): the robot drives in, the goal beyond is refused
  (or reached, if it squeezes through), then a goal back in the room must be reached without contact.

The pybullet version of the cafe legs is tests/test/cafe_aisles.test (figures in the README).

    python tools/bench.py -k aisles [--quick]
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "src"))
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "test"))  # unicycle_nav (test-only helper)

import numpy as np  # noqa: E402
from unicycle_nav import Run, dead_end_map, random_dead_end, slot_map  # noqa: E402

from chefbot_common.geometry import Pose2D  # noqa: E402
from chefbot_common.map_io import load_map  # noqa: E402
from chefbot_common.tables import load_tables  # noqa: E402
from chefbot_navigation.navigator import Goal  # noqa: E402
from chefbot_navigation.time_limit import MotionLimits, simple_limit  # noqa: E402

MAPS = ROOT / "chefbot_navigation" / "maps"
RATIO_GOAL = 1.5
REFUSE_GOAL_S = 10.0


def _cafe(urdf: str, names: list[str] | None) -> list[dict]:
    tables = load_tables(MAPS / "cafe_tables.yaml")
    home = tables["home"]
    run = Run(load_map(MAPS / "cafe_map.yaml"), urdf, Pose2D(home.x, home.y, home.yaw))
    lim = MotionLimits(run.ctrl.max_vel_x, run.ctrl.max_vel_theta, run.ctrl.acc_lim_x, run.ctrl.acc_lim_x,
                       run.ctrl.acc_lim_theta)
    rows = []
    for name in (names or [n for n in tables if n != "home"]) + ["home"]:
        tg = tables[name]
        yaw0 = run.pose.yaw
        res, took, touches, _, _, first = run.go(Goal(tg.x, tg.y, tg.yaw))
        limit = simple_limit(first.points, lim, yaw0, tg.yaw) if first is not None else float("nan")
        ok = res.outcome == "succeeded"
        rows.append({"bench": "aisles", "case": f"cafe {name} (unicycle, sim s)", "metric": "time / limit",
                     "ours": float(took / limit), "reference": float(limit), "reference_name": "simple limit (s)",
                     "goal": f"<= {RATIO_GOAL:g}, reached, 0 contacts",
                     "met": bool(ok and touches == 0 and took <= RATIO_GOAL * limit)})
    return rows


def _passages(urdf: str, widths: list[float]) -> list[dict]:
    taken, rows = [], []
    for width in widths:
        run = Run(slot_map(width), urdf, Pose2D(1.0, 1.2, 0.0))
        res, took, touches, events, _, _ = run.go(Goal(5.0, 1.5, 0.0))
        if res.outcome == "succeeded" and touches == 0:
            taken.append(width)
            continue
        # from the first "blocked" status (the robot stopped at the mouth) to the abort with the reason
        blocked = [t for t, e in run.timeline if e.startswith("blocked")]
        report = took - blocked[0] if blocked else 0.0
        rows.append({"bench": "aisles", "case": f"passage {width:.2f} m: refused ({res.text[:60]})",
                     "metric": "s blocked -> abort", "ours": float(report), "reference": None, "reference_name": None,
                     "goal": f"<= {REFUSE_GOAL_S:g} s with the reason",
                     "met": bool(report <= REFUSE_GOAL_S and res.outcome == "aborted")})
    rows.append({"bench": "aisles", "case": f"passages {widths[0]:.2f}-{widths[-1]:.2f} m", "metric":
                 "smallest taken (m)", "ours": min(taken) if taken else float("nan"), "reference": 0.30,
                 "reference_name": "robot width (m)", "goal": "<= 0.50 (the cafe's narrowest)",
                 "met": bool(taken) and min(taken) <= 0.50})
    return rows


def _dead_ends(urdf: str, n: int, seed: int = 1) -> list[dict]:
    rng = np.random.default_rng(seed)
    counts = {"refused": [0, 0], "passed": [0, 0]}      # kind -> [runs, next goals reached without contact]
    for _ in range(n):
        shape, start, beyond, back = random_dead_end(rng)
        run = Run(dead_end_map(*shape), urdf, start)
        first, _, touches, _, _, _ = run.go(Goal(*beyond, None), t_max=120.0)
        kind = "passed" if first.outcome == "succeeded" else "refused"
        try:
            res, _, touches2, _, _, _ = run.go(Goal(*back, None), t_max=150.0)
            ok = res.outcome == "succeeded" and touches + touches2 == 0
        except AssertionError:      # no outcome within t_max
            ok = False
        counts[kind][0] += 1
        counts[kind][1] += ok
    rows = []
    for kind, what in (("refused", "refused at the gap"), ("passed", "squeezed through the gap")):
        runs, ok = counts[kind]
        rows.append({"bench": "aisles", "case": f"dead ends ({n} generated, seed {seed}): {what}, next goal in "
                     f"the room", "metric": "next goals reached (fraction)",
                     "ours": float(ok / runs) if runs else float("nan"), "reference": float(runs),
                     "reference_name": "runs", "goal": "all, 0 contacts" if kind == "refused" else "(reported)",
                     "met": bool(ok == runs) if kind == "refused" else True})
    return rows


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see tools/bench.py)."""
    from chefbot_description.model import expand_xacro

    urdf = expand_xacro()
    rows = _cafe(urdf, ["table_s3", "table_n3"] if quick else None)
    rows += _passages(urdf, [0.33, 0.38] if quick else [0.30, 0.33, 0.35, 0.36, 0.38, 0.40, 0.45])
    rows += _dead_ends(urdf, 6 if quick else 60)
    return rows
