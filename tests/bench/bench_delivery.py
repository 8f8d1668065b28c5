"""Delivery time to every table vs the physical limit, and the real-time factor of the whole stack.

Runs `make demo`'s driver (tools/demo.py: pybullet hotel + map server +
localization + move_base, a real move_base client) with the simulator uncapped
(CHEFBOT_DEMO_RTF=0, as fast as the machine goes), then reads
build/demo/delivery.json.  Per table: sim seconds from goal to arrival next to
the time-optimal limit along the plan (chefbot_navigation.time_limit.profile_limit:
0.35 m/s, 2.5 rad/s, 0.8 m/s², 3 rad/s², turns at both ends); goal ≤ 1.15 × limit
(the end-to-end issue's).
The run's sim-seconds per wall-second is the full-stack real-time factor
(goal ≥ 1.0; Gazebo 7 with the book's Kinect world: 0.22).
The demo's plots (trajectory over the map, localization error, leg times vs limit;
tools/plots.py) are copied to bench-results/ next to the figures.
"""
from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]


def run(quick: bool = False) -> list[dict]:
    env = dict(os.environ, CHEFBOT_DEMO_RTF="0")
    if quick:
        env["CHEFBOT_DEMO_TABLES"] = "table_1,table_5"
    result = ROOT / "build" / "demo" / "delivery.json"
    result.unlink(missing_ok=True)
    for png in result.parent.glob("*.png"):   # no stale plots from an earlier run
        png.unlink()
    proc = subprocess.run([sys.executable, str(ROOT / "tools" / "demo.py")], env=env, capture_output=True,
                          text=True, timeout=1800, start_new_session=True)
    if not result.exists():
        raise RuntimeError(f"demo produced no results (exit {proc.returncode}):\n{proc.stdout[-3000:]}")
    data = json.loads(result.read_text())
    out = ROOT / "bench-results"
    out.mkdir(exist_ok=True)
    for png in sorted(result.parent.glob("*.png")):
        shutil.copy2(png, out / png.name)
        print(f"[bench] plot: {(out / png.name).relative_to(ROOT)}", flush=True)
    rows = []
    for leg in data["legs"]:
        limit = leg["limit_s"]
        goal = 1.15 * limit
        rows.append({"bench": "delivery", "case": leg["name"] + ("" if leg["ok"] else f" ({leg['state']})"),
                     "metric": "s (sim) to arrive", "ours": leg["seconds"] if leg["ok"] else None,
                     "reference": limit, "reference_name": "time-optimal limit along the plan",
                     "goal": f"<= {goal:.1f} s", "met": bool(leg["ok"] and leg["seconds"] <= goal)})
    for leg in data["legs"]:
        rows.append({"bench": "delivery", "case": f"{leg['name']} final ground-truth error", "metric": "m",
                     "ours": leg["xy_error"], "reference": 0.15, "reference_name": "book xy_goal_tolerance",
                     "goal": "<= 0.05", "met": leg["xy_error"] <= 0.05})
    rtf = data["sim_seconds"] / data["wall_seconds"] if data["wall_seconds"] > 0 else 0.0
    rows.append({"bench": "delivery", "case": "full stack (sim + nav + client), sim uncapped",
                 "metric": "x real time", "ours": rtf, "reference": 0.22,
                 "reference_name": "Gazebo 7 + Kinect (book)", "goal": ">= 1.0", "met": rtf >= 1.0})
    return rows


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(r)
