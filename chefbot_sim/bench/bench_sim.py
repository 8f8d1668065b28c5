"""Benchmark: the sim core (physics + sensors at their rates, no ROS) as a
multiple of real time in the hotel world.

    python chefbot_sim/bench/bench_sim.py [--quick]

Reference: the book reports Gazebo 7 running the ChefBot hotel at a real-time
factor of about 0.5-0.6 by default and 0.22 with the Kinect plugin.
"""
from __future__ import annotations

import math
import sys
import time
from pathlib import Path

PKG = Path(__file__).resolve().parents[1]
REFERENCE_NAME = "Gazebo 7 (book, reported)"
GOAL = 20.0


def _measure(urdf: str, sim_seconds: float, sensors: str) -> float:
    from chefbot_sim.sim import SENSORS, SimOptions, Simulator
    from chefbot_sim.world import load_world

    sim = Simulator(urdf, load_world(PKG / "worlds" / "hotel.yaml"), options=SimOptions(seed=1))
    try:
        if sensors == "none":
            for k in SENSORS:
                sim.set_enabled(k, False)
        elif sensors == "no_rgb":
            sim.set_enabled("rgb", False)
        sim.run(0.5)  # settle on the wheels, warm caches
        t0 = time.perf_counter()
        steps_per_cmd = 24  # a cmd_vel every 0.1 s of sim time, like a 10 Hz planner
        n = int(round(sim_seconds / 0.1))
        for i in range(n):
            # circles of 0.8 m radius in the free area west of the tables,
            # wobbling a little so the depth image keeps changing
            sim.set_cmd_vel(0.25, 0.3 + 0.05 * math.sin(i * 0.1))
            sim.step(steps_per_cmd)
        wall = time.perf_counter() - t0
    finally:
        sim.close()
    return sim_seconds / wall


def run(quick: bool = False) -> list[dict]:
    """Rows: sim-core speed as a real-time multiple for three sensor loads."""
    from chefbot_description.model import expand_xacro

    urdf = expand_xacro()
    seconds = 5.0 if quick else 30.0
    cases = [
        ("hotel: physics + all sensors (depth 10 Hz, rgb 2 Hz, imu 50 Hz, sonar 10 Hz, ...)", "all", 0.22),
        ("hotel: physics + sensors without rgb", "no_rgb", 0.22),
        ("hotel: physics only", "none", 0.55),
    ]
    rows = []
    for name, sensors, ref in cases:
        ours = _measure(urdf, seconds, sensors)
        rows.append({"bench": "sim", "case": name, "metric": "x real time", "ours": round(ours, 2),
                     "reference": ref, "reference_name": REFERENCE_NAME, "goal": f">= {GOAL:g}x",
                     "met": ours >= GOAL})
    return rows


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(f"{row['case']:<85} {row['ours']:>7.1f}x  (ref {row['reference']}x {row['reference_name']}; "
              f"goal {row['goal']}: {'met' if row['met'] else 'NOT met'})")
