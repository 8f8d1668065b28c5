#!/usr/bin/env python3
"""Sim-time rate of a chefbot_sim launch through ROS, on a private master.

    python chefbot_sim/bench/ros_rate.py [--seconds 20] [launch args ...]
    e.g. ... ros_rate.py --seconds 20 real_time_factor:=0
         ... ros_rate.py drive:=firmware pty_link:=/tmp/bench_lp --drive-forward

Starts ``roslaunch chefbot_sim chefbot_hotel_world.launch <args>`` with its own
master on a free port (own session, so everything is stopped at the end),
subscribes to /clock (which also makes the node publish it) and prints one
JSON line: sim seconds per wall second over the window, and, with
``--drive-forward``, the ground-truth and wheel-odometry distances of a
10 sim-second drive at cmd_vel 0.2 m/s (sent at 10 Hz of sim time), taken with
the robot at rest again (to see whether the real-time driver chain keeps up).
Used by bench_sim.py in a child process (rospy cannot re-init).
"""
from __future__ import annotations

import argparse
import json
import math
import os
import sys
import threading
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from procs import ProcessGroup, free_port  # the workspace's tools/


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--seconds", type=float, default=20.0, help="measuring window, wall s")
    ap.add_argument("--warmup", type=float, default=30.0, help="longest wait for the sim to start, wall s")
    ap.add_argument("--drive-forward", action="store_true",
                    help="publish cmd_vel 0.2 m/s for --drive-sim-seconds, then 0, and compare distances")
    ap.add_argument("--drive-sim-seconds", type=float, default=10.0,
                    help="sim seconds of driving forward (2 m at 0.2 m/s: clear of the hotel's walls)")
    ap.add_argument("--launch", nargs=2, default=("chefbot_sim", "chefbot_hotel_world.launch"),
                    metavar=("PKG", "FILE"), help="launch file to measure (default: the hotel world)")
    ap.add_argument("--subscribe", nargs="*", default=[], metavar="TOPIC",
                    help="also subscribe to these topics (raw bytes, like RViz), e.g. the camera's")
    args, launch_args = ap.parse_known_args()
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOSTNAME="127.0.0.1")
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_HOSTNAME="127.0.0.1")
    # ProcessGroup: its own session, and at the end its nodes too (roslaunch starts each node in a
    # session of its own, so killing roslaunch's group alone could leave its master running)
    with ProcessGroup(["roslaunch", "-p", str(port), *args.launch, *launch_args], env=env):
        import rospy
        from geometry_msgs.msg import Twist
        from nav_msgs.msg import Odometry
        from rosgraph_msgs.msg import Clock

        deadline = time.monotonic() + args.warmup
        while True:  # the master comes up with roslaunch
            try:
                rospy.init_node("chefbot_sim_bench", anonymous=True, disable_signals=True)
                break
            except Exception:  # master not up yet
                if time.monotonic() > deadline:
                    raise
                time.sleep(0.5)
        lock = threading.Lock()
        last = {"clock": -1.0, "gt": None, "odom": None}

        def on_clock(m: Clock) -> None:
            with lock:
                last["clock"] = m.clock.to_sec()

        def pose(m: Odometry) -> tuple[float, float]:
            return m.pose.pose.position.x, m.pose.pose.position.y

        rospy.Subscriber("/clock", Clock, on_clock, tcp_nodelay=True)
        received = {t: 0 for t in args.subscribe}
        for topic in args.subscribe:
            rospy.Subscriber(topic, rospy.AnyMsg, lambda _m, t=topic: received.__setitem__(t, received[t] + 1),
                             queue_size=2, buff_size=2 ** 25)
        rospy.Subscriber("ground_truth/odom", Odometry, lambda m: last.__setitem__("gt", pose(m)))
        rospy.Subscriber("odom", Odometry, lambda m: last.__setitem__("odom", pose(m)))
        cmd = rospy.Publisher("cmd_vel", Twist, queue_size=1)
        while last["clock"] < 1.0 or (args.drive_forward and last["odom"] is None):
            if time.monotonic() > deadline:
                raise RuntimeError("the sim did not start (no /clock past 1 s, or no odom)")
            time.sleep(0.1)
        time.sleep(2.0)  # settle

        def tick(v: float) -> None:
            if args.drive_forward:
                t = Twist()
                t.linear.x = v
                cmd.publish(t)
        with lock:
            sim0, gt0, od0 = last["clock"], last["gt"], last["odom"]
        wall0 = time.monotonic()
        sent, at_rest = -1.0, None
        while time.monotonic() - wall0 < args.seconds:
            # cmd_vel at 10 Hz of sim time, as a sim-time client (move_base) sends it however fast the
            # sim runs; forward for --drive-sim-seconds, then zero, and the distances are taken once
            # the robot has been at rest for 2 s of sim time (so no lag of either source counts)
            with lock:
                now = last["clock"]
            if now - sent >= 0.1:
                tick(0.2 if now - sim0 < args.drive_sim_seconds else 0.0)
                sent = now
            if at_rest is None and now - sim0 >= args.drive_sim_seconds + 2.0:
                with lock:
                    at_rest = last["gt"], last["odom"]
            time.sleep(0.002)
        with lock:
            sim1 = last["clock"]
        wall = time.monotonic() - wall0
        out = {"sim_seconds": sim1 - sim0, "wall_seconds": wall, "x_real_time": (sim1 - sim0) / wall,
               "received": received}
        if args.drive_forward and gt0 and od0 and at_rest and at_rest[0] and at_rest[1]:
            out["ground_truth_m"] = math.dist(gt0, at_rest[0])
            out["odom_m"] = math.dist(od0, at_rest[1])
        print(json.dumps(out), flush=True)
        rospy.signal_shutdown("done")
        return 0


if __name__ == "__main__":
    sys.exit(main())
