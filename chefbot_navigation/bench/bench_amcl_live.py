"""amcl's sustained update rate with the whole stack running at real time (issue goal: >= 10 updates/s).

The shipped amcl updates the filter only after ``update_min_d``/``update_min_a`` of
travel (AMCL's gating), so its rate in the demo follows the robot's speed (3-4.5/s
mean).  This benchmark asks what the node can sustain: the hotel demo stack
(pybullet sim at real_time_factor 1, firmware-in-the-loop drive with the IMU
heading, depth_to_scan, map_server, amcl, move_base, the ``deliver`` client)
with amcl's gating off (``update_min_d`` = ``update_min_a`` = 0: every 10 Hz scan
is a full filter update: motion model, 2000 particles x 60 beams, resampling),
while move_base drives home -> table_1 -> table_5 -> home.

Figures, over the route: filter updates per wall second
(``amcl_pose`` is published once per update), scans per wall second (the
ceiling: one update per scan), the sim's real-time factor, amcl's mean update
cost from its /diagnostics, and the localization error against ground truth at
each update (ground truth is read here, by the benchmark, never by amcl).
Reference: the same stack with the shipped gating.  The depth camera gives ~10 scans/s, so the
update rate cannot exceed that; the >= 10/s goal is judged as capacity (1000 / amcl's mean ms per
update) plus "nearly every scan is an update" (>= 90 %: at rest, and with no valid beam in front of
a table face, there is none, as in amcl).

``run()`` re-executes this file in a subprocess per case (rospy allows one node
per process) and reads its JSON.
"""
from __future__ import annotations

import bisect
import json
import math
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np
import yaml

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
from procs import ProcessGroup, free_port, run_captured, stop_on_sigterm  # noqa: E402  (stdlib only)

PARAMS = ROOT / "chefbot_navigation" / "param" / "amcl.yaml"
TABLES = ROOT / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml"
ROUTE = ["table_1", "table_5", "home"]
GOAL_UPDATES = 10.0     # updates/s sustained (issue 12)


def measure(gated: bool, out: Path) -> None:
    """Run the stack once and write the figures to ``out`` (JSON)."""
    import rosgraph
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry
    from rosgraph_msgs.msg import Clock
    from sensor_msgs.msg import LaserScan

    from chefbot_common.geometry import wrap_angle, yaw_from_quaternion

    tmp = Path(tempfile.mkdtemp(prefix="chefbot_bench_amcl_live_"))
    params = yaml.safe_load(PARAMS.read_text())
    if not gated:
        params.update(update_min_d=0.0, update_min_a=0.0)
    (tmp / "amcl.yaml").write_text(yaml.safe_dump(params))
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOME=str(tmp / "ros_home"))
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_HOME=env["ROS_HOME"])
    cmd = ["roslaunch", "-p", str(port), "chefbot_sim", "navigation_demo.launch", "drive:=firmware", "use_imu:=true",
           f"map_file:={ROOT / 'chefbot_navigation' / 'maps' / 'hotel_world_map.yaml'}",   # TABLES' frame
           f"pty_link:={tmp / 'launchpad'}", "real_time_factor:=1", f"amcl_params:={tmp / 'amcl.yaml'}"]
    lock = threading.Lock()
    truth: list[tuple[float, float, float, float]] = []    # t sim, x, y, yaw
    moving: list[float] = []                                # wall times of truth samples with the robot moving
    poses: list[tuple[float, float, float, float, float]] = []   # wall, t sim, x, y, yaw
    scans: list[float] = []                                 # wall receive times
    clock: list[tuple[float, float]] = []                   # (wall, sim) samples
    diag: list[float] = []                                  # amcl's update_ms_mean samples

    def on_truth(m: Odometry) -> None:
        p, q = m.pose.pose.position, m.pose.pose.orientation
        tw = m.twist.twist
        with lock:
            truth.append((m.header.stamp.to_sec(), p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)))
            if math.hypot(tw.linear.x, tw.linear.y) > 0.05 or abs(tw.angular.z) > 0.2:
                moving.append(time.monotonic())

    def on_pose(m: PoseWithCovarianceStamped) -> None:
        p, q = m.pose.pose.position, m.pose.pose.orientation
        with lock:
            poses.append((time.monotonic(), m.header.stamp.to_sec(), p.x, p.y,
                          yaw_from_quaternion(q.x, q.y, q.z, q.w)))

    def on_scan(_m) -> None:
        with lock:
            scans.append(time.monotonic())

    def on_clock(m: Clock) -> None:
        with lock:
            if not clock or time.monotonic() - clock[-1][0] >= 0.5:
                clock.append((time.monotonic(), m.clock.to_sec()))

    def on_diag(m: DiagnosticArray) -> None:
        for st in m.status:
            if st.name.endswith("amcl: localization"):
                v = {kv.key: kv.value for kv in st.values}
                if v.get("update_ms_mean", "nan") != "nan":
                    with lock:
                        diag.append(float(v["update_ms_mean"]))

    with ProcessGroup(cmd, env=env, log=tmp / "roslaunch.log") as launch:
        deadline = time.monotonic() + 120
        while not rosgraph.Master("/bench_amcl_live").is_online():
            if time.monotonic() > deadline or launch.poll() is not None:
                raise RuntimeError(f"no ROS master from roslaunch; see {tmp / 'roslaunch.log'}")
            time.sleep(0.5)
        rospy.init_node("bench_amcl_live", anonymous=True, disable_signals=True)
        rospy.Subscriber("ground_truth/odom", Odometry, on_truth, queue_size=50)
        rospy.Subscriber("amcl_pose", PoseWithCovarianceStamped, on_pose, queue_size=50)
        rospy.Subscriber("scan", LaserScan, on_scan, queue_size=50)
        rospy.Subscriber("clock", Clock, on_clock, queue_size=10)
        rospy.Subscriber("diagnostics", DiagnosticArray, on_diag, queue_size=20)
        t0 = time.monotonic()
        drive = subprocess.run(["rosrun", "chefbot_navigation", "deliver", *ROUTE, "--tables", str(TABLES),
                                "--timeout", "240"], env=env, capture_output=True, text=True, timeout=900)
        t1 = time.monotonic()
        if launch.poll() is not None:
            raise RuntimeError(f"the stack died (exit {launch.poll()}); see {tmp / 'roslaunch.log'}")
    rospy.signal_shutdown("done")
    with lock:
        truth_t = [s[0] for s in truth]
        errs = []
        for _, ts, x, y, yaw in poses:
            i = bisect.bisect_left(truth_t, ts)
            if 0 < i < len(truth) and truth_t[i] - ts < 0.05:
                _, gx, gy, gyaw = truth[i]
                errs.append((math.hypot(x - gx, y - gy), abs(wrap_angle(yaw - gyaw))))
        updates = [w for w, *_ in poses if t0 <= w <= t1]
        nscans = [w for w in scans if t0 <= w <= t1]
        span = [c for c in clock if t0 <= c[0] <= t1]
        moving_s = np.array(moving)
    wall = t1 - t0
    # the worst 10 s window of updates while the robot drives or turns all through it (sustained, not
    # only on average; a robot at rest gets no update, as in amcl)
    starts = [t0 + 0.5 * k for k in range(int(2 * (wall - 10.0)))]
    driving = [s for s in starts if all(np.any((moving_s >= a) & (moving_s < a + 1.0))
                                        for a in np.arange(s, s + 10.0, 1.0))]
    worst = min((sum(1 for u in updates if s <= u < s + 10.0) / 10.0 for s in driving), default=math.nan)
    result = {
        "delivered": drive.returncode == 0, "deliver_tail": drive.stdout[-600:] + drive.stderr[-600:],
        "wall_s": wall, "updates_per_s": len(updates) / wall, "updates_per_s_worst_10s": worst,
        "scans_per_s": len(nscans) / wall,
        "rtf": (span[-1][1] - span[0][1]) / (span[-1][0] - span[0][0]) if len(span) > 1 else math.nan,
        "update_ms_mean": statistics.median(diag) if diag else math.nan,
        "rms_xy": math.sqrt(statistics.fmean(e[0] ** 2 for e in errs)) if errs else math.nan,
        "rms_yaw": math.sqrt(statistics.fmean(e[1] ** 2 for e in errs)) if errs else math.nan,
        "max_xy": max((e[0] for e in errs), default=math.nan),
    }
    out.write_text(json.dumps(result))
    shutil.rmtree(tmp, ignore_errors=True)   # kept on failure: the exception names its roslaunch.log


def _case(gated: bool) -> dict:
    with tempfile.TemporaryDirectory(prefix="chefbot_bench_amcl_live_out_") as d:
        out = Path(d) / "r.json"
        proc = run_captured([sys.executable, __file__, "--measure", "gated" if gated else "every-scan", str(out)],
                            timeout=1200)
        if not out.exists():
            raise RuntimeError(f"bench_amcl_live produced nothing (exit {proc.returncode}):\n{proc.stderr[-2000:]}")
        return json.loads(out.read_text())


def run(quick: bool = False) -> list[dict]:
    ours = _case(gated=False)
    ref = _case(gated=True) if not quick else None
    case = f"whole stack at rtf 1, firmware drive, {' -> '.join(['home', *ROUTE])}"
    rows = []

    def row(metric: str, key: str, goal: str | None, met: bool | None) -> None:
        rows.append({"bench": "amcl_live", "case": f"{case}, every scan updates", "metric": metric,
                     "ours": ours[key], "reference": ref[key] if ref else None,
                     "reference_name": "shipped update_min_d/a (gated)" if ref else None, "goal": goal, "met": met})

    # the camera's ~10 scans/s cap the rate: the goal is met when (nearly) every scan taken while moving
    # is a filter update and one update costs well under 1/10 s (the capacity row)
    row("filter updates / s (wall), mean", "updates_per_s", "~ scans/s (the camera's 10 Hz caps it)",
        ours["updates_per_s"] >= 0.9 * ours["scans_per_s"])
    ours["capacity"] = 1000.0 / ours["update_ms_mean"] if ours["update_ms_mean"] > 0 else math.nan
    if ref:
        ref["capacity"] = 1000.0 / ref["update_ms_mean"] if ref["update_ms_mean"] > 0 else math.nan
    row("capacity: updates / s at amcl's mean cost (1000 / ms)", "capacity", f">= {GOAL_UPDATES:g}",
        ours["capacity"] >= GOAL_UPDATES)
    row("filter updates / s (wall), worst 10 s", "updates_per_s_worst_10s", None, None)
    row("scans / s (wall): the ceiling", "scans_per_s", None, None)
    row("sim real-time factor", "rtf", ">= 0.95", ours["rtf"] >= 0.95)
    row("ms / update (amcl's mean)", "update_ms_mean", None, None)
    row("RMS position error m", "rms_xy", "<= 0.05", ours["rms_xy"] <= 0.05)
    row("RMS yaw error rad", "rms_yaw", "<= 0.05", ours["rms_yaw"] <= 0.05)
    row("max position error m", "max_xy", "<= 0.15", ours["max_xy"] <= 0.15)
    rows.append({"bench": "amcl_live", "case": f"{case}, every scan updates", "metric": "route delivered",
                 "ours": float(ours["delivered"]), "reference": float(ref["delivered"]) if ref else None,
                 "reference_name": "gated" if ref else None, "goal": "1", "met": ours["delivered"]})
    return rows


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--measure":
        stop_on_sigterm()
        measure(gated=sys.argv[2] == "gated", out=Path(sys.argv[3]))
    else:
        for r in run(quick="--quick" in sys.argv):
            print(r)
