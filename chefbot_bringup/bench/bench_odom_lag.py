"""Lag of the odometry tf behind the robot: tf ``odom → base_footprint`` against ground truth.

Runs the simulated hotel (``chefbot_sim chefbot_hotel_world.launch``; firmware drive =
our firmware core on a pty + the unmodified robot_standalone.launch with diff_tf, IMU
heading as in ``make demo``; or the plugin drive) on a private master, turns the robot
on the spot at ``--w`` rad/s (both ways, rests in between), and at every ``scan`` stamp
(what amcl pairs odometry with) looks the odometry tf up at that stamp and compares its
heading with the simulator's ground truth interpolated at the same stamp.

Reported: the heading error at the scan stamps during the turns relative to the offset
at rest (odometry's frame is not the world's), and the lag ``tau`` (s) that best explains
it: the shift of ground truth that minimises the spread of ``yaw_gt(t - tau) - yaw_odom(t)``.
A bench (reads ground truth); not a product node.

    python chefbot_bringup/bench/bench_odom_lag.py [--drive firmware|plugin] [--w 2.0]

``run()`` re-executes this file in a subprocess (rospy allows one node per process).
"""
from __future__ import annotations

import argparse
import bisect
import json
import math
import os
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
from procs import ProcessGroup, free_port, run_captured, stop_on_sigterm  # noqa: E402  (stdlib only)

GOAL_LAG_S = 0.010     # tf odom -> base_footprint no more than 10 ms behind the robot


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def analyse(gt_t: np.ndarray, gt_yaw: np.ndarray, st: np.ndarray, odom_yaw: np.ndarray,
            moving: np.ndarray) -> dict:
    """Lag and heading errors from ground truth (times s, unwrapped yaw rad) and the odometry
    heading ``odom_yaw`` (rad) at the scan stamps ``st`` (s); ``moving``: stamps during a turn."""
    gt_u = np.unwrap(gt_yaw)

    def offsets(tau: float) -> np.ndarray:
        g = np.interp(st - tau, gt_t, gt_u)
        return np.angle(np.exp(1j * (g - odom_yaw)))

    rest = offsets(0.0)[~moving]
    base = float(np.angle(np.mean(np.exp(1j * rest)))) if len(rest) else 0.0
    err = np.angle(np.exp(1j * (offsets(0.0) - base)))
    taus = np.arange(-0.05, 0.2001, 0.001)
    spread = [float(np.std(np.angle(np.exp(1j * (offsets(tau) - base))))) for tau in taus]
    return {"lag_s": float(taus[int(np.argmin(spread))]),
            "turn_err_deg_max": float(np.degrees(np.max(np.abs(err[moving])))) if moving.any() else 0.0,
            "turn_err_deg_mean": float(np.degrees(np.mean(np.abs(err[moving])))) if moving.any() else 0.0,
            "rest_err_deg_max": float(np.degrees(np.max(np.abs(err[~moving])))) if (~moving).any() else 0.0,
            "scans_turning": int(moving.sum()), "scans_rest": int((~moving).sum())}


def fit_lag(gt_t: np.ndarray, gt_yaw: np.ndarray, seg: np.ndarray) -> float:
    """Lag (s) of one rest-turn-rest segment (rows: scan stamp s, odometry yaw rad) fitted with a free
    offset and scale, ``yaw_odom(t) = a + k * yaw_gt(t - tau)``: wheel-only headings drift and mis-scale
    turns, which the constant-offset estimate of :func:`analyse` would read as lag."""
    seg = seg[(seg[:, 0] >= gt_t[0] + 0.2) & (seg[:, 0] <= gt_t[-1])]
    gt_u, od_u = np.unwrap(gt_yaw), np.unwrap(seg[:, 1])
    best = (math.inf, 0.0)
    for tau in np.arange(-0.05, 0.2001, 0.001):
        a = np.column_stack([np.ones(len(seg)), np.interp(seg[:, 0] - tau, gt_t, gt_u)])
        res = np.linalg.lstsq(a, od_u, rcond=None)[1]
        best = min(best, (float(res[0]) if len(res) else math.inf, float(tau)))
    return best[1]


def measure(drive: str, w: float, turns: int, use_imu: bool = True) -> dict:
    import rosgraph
    import rospy
    import tf2_ros
    from geometry_msgs.msg import Twist
    from nav_msgs.msg import Odometry
    from sensor_msgs.msg import Imu, LaserScan

    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}")
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    tmp = Path(tempfile.mkdtemp(prefix="chefbot_odom_lag_"))
    launch = ["roslaunch", "--wait", "chefbot_sim", "chefbot_hotel_world.launch", f"drive:={drive}",
              f"use_imu:={str(use_imu).lower()}", "real_time_factor:=1.0", f"pty_link:={tmp / 'launchpad'}"]
    gt: list[tuple[float, float]] = []
    scans: list[float] = []
    with ProcessGroup(["roscore", "-p", str(port)], env=env, log=tmp / "roscore.log"), \
            ProcessGroup(launch, env=env, log=tmp / "launch.log"):
        deadline = time.monotonic() + 120
        master = rosgraph.Master("/bench")
        while not (master.is_online() and master.hasParam("/use_sim_time")):   # sim time before init_node
            if time.monotonic() > deadline:
                raise RuntimeError("no ROS master with /use_sim_time")
            time.sleep(0.1)
        rospy.init_node("odom_lag_bench", disable_signals=True)
        buf = tf2_ros.Buffer(rospy.Duration(60.0))
        tf2_ros.TransformListener(buf)
        rospy.Subscriber("ground_truth/odom", Odometry,
                         lambda m: gt.append((m.header.stamp.to_sec(), _yaw(m.pose.pose.orientation))))
        rospy.Subscriber("scan", LaserScan, lambda m: scans.append(m.header.stamp.to_sec()))
        imu: list[tuple[float, float]] = []   # imu/data (launchpad_node stamps it when the line arrives)
        rospy.Subscriber("imu/data", Imu, lambda m: imu.append((m.header.stamp.to_sec(), _yaw(m.orientation))))
        pub = rospy.Publisher("cmd_vel", Twist, queue_size=1)
        while not (gt and scans and buf.can_transform("odom", "base_footprint", rospy.Time(0))):
            if time.monotonic() > deadline:
                raise RuntimeError(f"sim did not come up (log {tmp / 'launch.log'})")
            time.sleep(0.2)
        # phases: (duration s of sim time, w rad/s)
        phases = [(2.0, 0.0)]
        for k in range(turns):
            phases += [(3.0, w if k % 2 == 0 else -w), (2.0, 0.0)]
        spans = []
        for dur, wz in phases:
            t0 = rospy.get_time()
            cmd = Twist()
            cmd.angular.z = wz
            while rospy.get_time() - t0 < dur:
                pub.publish(cmd)
                time.sleep(0.05)
            spans.append((t0, rospy.get_time(), wz))
        pub.publish(Twist())
        time.sleep(1.0)
        st, odom_yaw, moving = [], [], []
        segments: list[list[tuple[float, float]]] = [[] for _ in range(turns)]   # rest-turn-rest, every scan
        for s in scans:
            if not spans[0][0] + 0.5 < s < spans[-1][1]:
                continue
            try:
                tr = buf.lookup_transform("odom", "base_footprint", rospy.Time.from_sec(s))
            except tf2_ros.TransformException:
                continue
            phase = next((p for p in spans if p[0] <= s < p[1]), None)
            if phase is None:
                continue
            k = spans.index(phase)
            for j in {max((k - 1) // 2, 0), min(k // 2, turns - 1)}:
                segments[j].append((s, _yaw(tr.transform.rotation)))
            # "moving": steady turn (skip the first 0.8 s of spin-up); "rest": >= 1 s after a turn
            if phase[2] != 0.0 and s > phase[0] + 0.8:
                moving.append(True)
            elif phase[2] == 0.0 and s > phase[0] + 1.0:
                moving.append(False)
            else:
                continue
            st.append(s)
            odom_yaw.append(_yaw(tr.transform.rotation))
        rospy.signal_shutdown("bench done")
    gt.sort()
    print(f"spans {[(round(a, 2), round(b, 2), c) for a, b, c in spans]}, ground truth {len(gt)} "
          f"({gt[0][0]:.2f}..{gt[-1][0]:.2f} s), scans {len(scans)}, used {len(st)}", file=sys.stderr)
    gt_t = np.array([g[0] for g in gt])
    gt_yaw = np.array([g[1] for g in gt])
    # keep only stamps inside the ground truth record
    sel = [i for i, s in enumerate(st) if gt_t[0] <= s <= gt_t[-1]]
    res = analyse(gt_t, gt_yaw, np.array(st)[sel], np.array(odom_yaw)[sel], np.array(moving, dtype=bool)[sel])
    res.update(drive=drive, w=w, use_imu=use_imu)
    res["lag_fit_s"] = [fit_lag(gt_t, gt_yaw, np.array(seg)) for seg in segments]
    if imu:   # the IMU's own lag behind ground truth, at its stamps, over the whole run
        im = np.array([r for r in imu if spans[0][0] + 0.5 < r[0] < min(spans[-1][1], gt_t[-1])])
        res["imu_lag_s"] = fit_lag(gt_t, gt_yaw, im) if len(im) else None
    i = bisect.bisect_left(gt_t.tolist(), spans[1][0] + 1.5)
    res["w_measured"] = float((np.unwrap(gt_yaw)[i + 25] - np.unwrap(gt_yaw)[i]) / (gt_t[i + 25] - gt_t[i]))
    return res


def lag(drive: str, w: float, turns: int = 2, use_imu: bool = True) -> dict:
    """Measure in a fresh subprocess; returns the :func:`analyse` dict plus drive, w, use_imu, w_measured."""
    cmd = [sys.executable, __file__, "--measure", "--drive", drive, "--w", str(w), "--turns", str(turns)]
    cmd += [] if use_imu else ["--no-imu"]
    out = run_captured(cmd, timeout=600)
    if out.returncode != 0:
        raise RuntimeError(f"odometry lag bench failed:\n{out.stderr[-3000:]}")
    return json.loads(out.stdout.strip().splitlines()[-1])


def run(quick: bool = False) -> list[dict]:
    """Firmware drive (diff_tf, IMU heading); the full run also measures the plugin drive (the sim's
    own odometry, stamped at its physics time) as the reference."""
    fw = lag("firmware", 2.0, 2)
    ref = None if quick else lag("plugin", 2.0, 2)
    case = f"firmware drive, turning on the spot at {fw['w_measured']:.2f} rad/s, at the scan stamps"
    return [{"bench": "odometry lag", "case": f"{case}: tf odom->base_footprint behind ground truth",
             "metric": "ms", "ours": fw["lag_s"] * 1000, "reference": None if ref is None else ref["lag_s"] * 1000,
             "reference_name": "plugin drive" if ref else None, "goal": f"<= {GOAL_LAG_S * 1000:g} ms",
             "met": abs(fw["lag_s"]) <= GOAL_LAG_S},
            {"bench": "odometry lag", "case": f"{case}: mean heading error while turning", "metric": "deg",
             "ours": fw["turn_err_deg_mean"], "reference": None if ref is None else ref["turn_err_deg_mean"],
             "reference_name": "plugin drive" if ref else None, "goal": None, "met": None}]


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--measure", action="store_true", help="(internal) measure in this process")
    ap.add_argument("--drive", default="firmware", choices=("firmware", "plugin"))
    ap.add_argument("--w", type=float, default=2.0, help="turn rate (rad/s)")
    ap.add_argument("--turns", type=int, default=2)
    ap.add_argument("--no-imu", action="store_true", help="heading from the wheels (default: the IMU, as make demo)")
    a = ap.parse_args()
    if a.measure:
        stop_on_sigterm()
        print(json.dumps(measure(a.drive, a.w, a.turns, not a.no_imu)))
    else:
        print(json.dumps(lag(a.drive, a.w, a.turns, not a.no_imu), indent=1))
