#!/usr/bin/env python3
"""Narrow aisles benchmark (pure, no ROS): move_base's Navigator with the URDF footprint on a perfect
unicycle (test/unicycle_nav.py).

* the cafe test site (chefbot_navigation/maps/cafe_*.yaml, aisles 0.50-0.90 m): every table and
  home; per leg the time against the time-optimal limit (chefbot_navigation.time_limit.simple_limit:
  length / v_max + turns / w_max, goal <= 1.5x) and contacts of the collision bodies with the map;
* single passages 0.30-0.45 m wide: the smallest one taken, and for narrower ones the time from the
  first "blocked" report to the abort with the reason (goal <= 10 s).

The pybullet version of the cafe legs is tests/test/cafe_aisles.test (figures in the README).

    python tools/bench.py -k aisles [--quick]
"""
from __future__ import annotations

import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "src"))
sys.path.insert(0, str(ROOT / "chefbot_navigation" / "test"))  # unicycle_nav (test-only helper)

from unicycle_nav import Run, slot_map  # noqa: E402

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


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see tools/bench.py)."""
    from chefbot_description.model import expand_xacro

    urdf = expand_xacro()
    rows = _cafe(urdf, ["table_s3", "table_n3"] if quick else None)
    rows += _passages(urdf, [0.33, 0.38] if quick else [0.30, 0.33, 0.35, 0.36, 0.38, 0.40, 0.45])
    return rows
