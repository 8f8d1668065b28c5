"""Benchmark: the simulator as a multiple of real time in the hotel world.

    python chefbot_sim/bench/bench_sim.py [--quick]

Rows:
* the sim core alone (no ROS; physics + sensors at their rates), plugin drive,
  three sensor loads; and the firmware drive (our firmware core stepped every
  physics step, commands fed straight into it);
* the fleet core (chefbot_sim.fleet): 1, 2 and 3 robots in one hotel world, all sensors, each
  robot driving circles in the free area (they see each other);
* through ROS (not with --quick): ``chefbot_hotel_world.launch
  real_time_factor:=0`` on a private master (robot idle, depth_to_scan
  subscribed), measured as sim seconds per wall second over 20 s by
  ``ros_rate.py`` in a child process; and firmware mode with
  robot_standalone.launch driving 0.2 m/s, capped at real time (the default)
  and uncapped, with the wheel odometry's error against ground truth (what
  the cap protects).

Reference: the book reports Gazebo 7 running the ChefBot hotel at a real-time
factor of about 0.5-0.6 by default and 0.22 with the Kinect plugin.
"""
from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time
from pathlib import Path

PKG = Path(__file__).resolve().parents[1]
REFERENCE_NAME = "Gazebo 7 (book, reported)"
GOAL = 20.0
GOAL_ROS = 3.0


def _measure(urdf: str, sim_seconds: float, sensors: str, drive: str = "plugin") -> tuple[float, float]:
    """(sim s per wall s, sim s per CPU s of this process): on a loaded machine the
    second tells what one idle core would give."""
    from chefbot_sim.sim import SENSORS, SimOptions, Simulator
    from chefbot_sim.world import load_world

    # the RGB camera as these rows were always measured (80 x 60 at 2 Hz); the 320 x 240 / 10 Hz camera
    # and its clouds have their own rows in chefbot_vision/bench/bench_vision.py
    opts = SimOptions(seed=1, drive=drive, rgb_rate=2.0, rgb_width=80, rgb_height=60)
    sim = Simulator(urdf, load_world(PKG / "worlds" / "hotel.yaml"), options=opts)
    try:
        if sensors == "none":
            for k in SENSORS:
                sim.set_enabled(k, False)
        elif sensors == "no_rgb":
            sim.set_enabled("rgb", False)
        sim.run(0.5)  # settle on the wheels, warm caches
        t0, c0 = time.perf_counter(), time.process_time()
        steps_per_cmd = 24  # a cmd_vel every 0.1 s of sim time, like a 10 Hz planner
        n = int(round(sim_seconds / 0.1))
        for i in range(n):
            w = 0.3 + 0.05 * math.sin(i * 0.1)
            if drive == "plugin":
                # circles of 0.8 m radius in the free area west of the tables,
                # wobbling a little so the depth image keeps changing
                sim.set_cmd_vel(0.25, w)
                sim.step(steps_per_cmd)
            else:
                # motor commands straight into the firmware at the driver's 30 Hz
                left, right = (round((0.25 - w * 0.15) / 0.377 * 1023), round((0.25 + w * 0.15) / 0.377 * 1023))
                for _ in range(3):
                    sim.firmware.board.fw.feed(f"s {left} {right}\r".encode())
                    sim.step(steps_per_cmd // 3)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        sim.close()
    return sim_seconds / wall, sim_seconds / cpu


def _measure_fleet(urdf: str, sim_seconds: float, robots: int) -> tuple[float, float]:
    """(sim s per wall s, sim s per CPU s) of ``robots`` ChefBots in one hotel world, all sensors on,
    each driving 0.8 m circles west of the tables, 1.5 m apart (as hotel_fleet.yaml parks them)."""
    from chefbot_common.geometry import Pose2D
    from chefbot_sim.fleet import Fleet, RobotSpec
    from chefbot_sim.sim import SimOptions
    from chefbot_sim.world import load_world

    starts_y = (0.0, -1.5, 1.5)
    specs = [RobotSpec(f"chefbot{i + 1}", urdf, Pose2D(0.0, starts_y[i], 0.0),
                       SimOptions(seed=i + 1, rgb_rate=2.0, rgb_width=80, rgb_height=60)) for i in range(robots)]
    fleet = Fleet(load_world(PKG / "worlds" / "hotel.yaml"), specs)
    try:
        fleet.run(0.5)
        t0, c0 = time.perf_counter(), time.process_time()
        for i in range(int(round(sim_seconds / 0.1))):
            for sim in fleet.sims:
                sim.set_cmd_vel(0.25, 0.3 + 0.05 * math.sin(i * 0.1))
            fleet.step(24)
        wall, cpu = time.perf_counter() - t0, time.process_time() - c0
    finally:
        fleet.close()
    return sim_seconds / wall, sim_seconds / cpu


def _ros_rate(args: list[str], seconds: float = 20.0) -> dict:
    """Run ros_rate.py (own master, own session) and return its JSON figures."""
    out = subprocess.run([sys.executable, str(PKG / "bench" / "ros_rate.py"), "--seconds", str(seconds), *args],
                         capture_output=True, text=True, timeout=seconds + 120)
    lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
    if out.returncode != 0 or not lines:
        raise RuntimeError(f"ros_rate.py {' '.join(args)} failed: {out.stderr[-500:]}")
    return json.loads(lines[-1])


def _row(case: str, metric: str, ours: float, ref: float | None, goal: str, met: bool) -> dict:
    return {"bench": "sim", "case": case, "metric": metric, "ours": round(ours, 3), "reference": ref,
            "reference_name": REFERENCE_NAME if ref is not None else None, "goal": goal, "met": met}


def run(quick: bool = False) -> list[dict]:
    """Rows: speed as a real-time multiple (core, firmware core, ROS) and the firmware
    mode's odometry error with and without the real-time cap."""
    from chefbot_description.model import expand_xacro

    urdf = expand_xacro()
    seconds = 5.0 if quick else 30.0
    cases = [
        ("hotel core: physics + all sensors (depth 10 Hz, rgb 80x60 2 Hz, imu 50 Hz, sonar 10 Hz, ...)", "all", 0.22),
        ("hotel core: physics + sensors without rgb", "no_rgb", 0.22),
        ("hotel core: physics only", "none", 0.55),
    ]
    rows = []
    cases.append(("hotel core, firmware drive: physics + firmware core + all sensors", "all", 0.22))
    for k, (name, sensors, ref) in enumerate(cases):
        ours, per_cpu = _measure(urdf, seconds, sensors, drive="firmware" if k == 3 else "plugin")
        rows.append(_row(name, "x real time", ours, ref, f">= {GOAL:g}x", ours >= GOAL))
        rows.append(_row(name + " [per CPU second: an idle core]", "x real time", per_cpu, ref,
                         f">= {GOAL:g}x", per_cpu >= GOAL))
    for n in (1, 2, 3):
        ours, per_cpu = _measure_fleet(urdf, seconds, n)
        goal = GOAL / n   # the core's goal shared by the robots
        rows.append(_row(f"hotel fleet core: {n} robot(s) in one world, all sensors", "x real time", ours, None,
                         f">= {goal:.3g}x", ours >= goal))
        rows.append(_row(f"hotel fleet core: {n} robot(s) in one world, all sensors [per CPU second]",
                         "x real time", per_cpu, None, f">= {goal:.3g}x", per_cpu >= goal))
    if quick:
        return rows
    tag = f"/tmp/chefbot_bench_lp_{os.getpid()}"
    r = _ros_rate(["real_time_factor:=0"])
    rows.append(_row("hotel node via ROS, plugin drive, rtf 0 (idle, depth_to_scan on)", "x real time",
                     r["x_real_time"], 0.22, f">= {GOAL_ROS:g}x", r["x_real_time"] >= GOAL_ROS))
    for label, extra in (("capped at 1x (firmware_max_rtf 1)", ["firmware_max_rtf:=1"]),
                         ("uncapped (rtf 0, default firmware_max_rtf 0)", ["real_time_factor:=0"])):
        r = _ros_rate(["--drive-forward", "drive:=firmware", f"pty_link:={tag}", *extra])
        uncapped = "uncapped" in label
        rows.append(_row(f"hotel node via ROS, firmware drive + robot_standalone, {label}", "x real time",
                         r["x_real_time"], None, f">= {GOAL_ROS:g}x" if uncapped else "-",
                         r["x_real_time"] >= GOAL_ROS if uncapped else True))
        if "odom_m" in r and r["ground_truth_m"] > 0.1:
            err = abs(r["odom_m"] - r["ground_truth_m"]) / r["ground_truth_m"] * 100.0
            rows.append(_row(f"firmware drive {label}: wheel odometry vs ground truth, 0.2 m/s", "% error",
                             err, None, "<= 3 %", err <= 3.0))
    return rows


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        ref = f"(ref {row['reference']}x {row['reference_name']}; " if row["reference"] is not None else "("
        print(f"{row['case']:<92} {row['ours']:>8.2f} {row['metric']:<12} {ref}"
              f"goal {row['goal']}: {'met' if row['met'] else 'NOT met'})")
