#!/usr/bin/env python3
"""Record amcl's /diagnostics next to the simulator's ground truth, one JSON line per status (a
developer's tool for localization failures; the ground truth is the TEST ORACLE, sim only).

    ROS_MASTER_URI=... python tools/amcl_trace.py OUT.jsonl      # until Ctrl-C
    python tools/amcl_trace.py --summary OUT.jsonl               # what happened, afterwards

Each line: sim time ``t``, the status ``level`` and ``msg``, every value amcl reports (particles,
mean_beam_fit, w_slow, w_fast, injected_last_resample, estimate_switches, x, y, yaw, std_xy ...)
and the ground truth ``gx``, ``gy`` at the same moment as the estimate: amcl's last ``amcl_pose``
(stamped with the scan its update used) against the ground truth interpolated at that stamp.  (The
diagnostics' x, y are that last update's estimate; against the newest ground truth instead, a
robot driving at 0.35 m/s showed a 5 cm "error" along its motion that was only the time between.)
The summary prints the lines where something happened: particles injected, the estimate switching
cluster, or the estimate over 0.15 m off. This is how the cafe's home-leg failure of 2026-11-23 was
traced to recovery injection (chefbot_navigation README, amcl "recovery").
"""
from __future__ import annotations

import argparse
import bisect
import json
import math
import sys
import threading


def summary(path: str, err_over: float = 0.15) -> list[str]:
    """Lines for the records where particles were injected, the estimate switched or was off."""
    out, switches = [], None
    with open(path) as f:
        for line in f:
            r = json.loads(line)
            if "x" not in r or "gx" not in r:
                continue
            err = math.hypot(float(r["x"]) - r["gx"], float(r["y"]) - r["gy"])
            w_slow, w_fast = float(r.get("w_slow", 0)), float(r.get("w_fast", 0))
            inj, sw = float(r.get("injected_last_resample", 0)), float(r.get("estimate_switches", 0))
            if inj > 0 or err > err_over or (switches is not None and sw != switches):
                ratio = w_fast / w_slow if w_slow else math.nan
                fit, std = float(r.get("mean_beam_fit", math.nan)), float(r.get("std_xy", 0))
                out.append(f"t {r['t']:7.1f}  fit {fit:.2f}  w_fast/w_slow {ratio:.2f}  injected {inj:4.0f}  "
                           f"switches {sw:3.0f}  std {std:.3f} m  error {err:.3f} m at ({r['gx']:.2f}, {r['gy']:.2f})")
            switches = sw
    return out


def truth_at(history: list[tuple[float, float, float]], t: float) -> tuple[float, float] | None:
    """Ground truth (x, y) at time ``t`` interpolated in ``history`` ((t, x, y), oldest first); None when
    ``t`` lies outside it."""
    if not history or t < history[0][0] or t > history[-1][0]:
        return None
    i = bisect.bisect_left([h[0] for h in history], t)
    if history[i][0] == t or i == 0:
        return history[i][1], history[i][2]
    (t0, x0, y0), (t1, x1, y1) = history[i - 1], history[i]
    a = (t - t0) / (t1 - t0)
    return x0 + a * (x1 - x0), y0 + a * (y1 - y0)


def record(path: str, keep_s: float = 10.0) -> None:
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from geometry_msgs.msg import PoseWithCovarianceStamped
    from nav_msgs.msg import Odometry

    history: list[tuple[float, float, float]] = []      # ground truth (t, x, y), the last keep_s seconds
    estimate: list[dict] = []                           # the last amcl_pose with the truth at its stamp
    lock = threading.Lock()                             # rospy calls each subscriber from its own thread

    def on_truth(msg: Odometry) -> None:
        t, p = msg.header.stamp.to_sec(), msg.pose.pose.position
        with lock:
            if history and t < history[-1][0]:
                history.clear()                         # time jumped back (sim restarted)
            history.append((t, p.x, p.y))
            while history and history[0][0] < t - keep_s:
                history.pop(0)

    def on_pose(msg: PoseWithCovarianceStamped) -> None:
        t, p = msg.header.stamp.to_sec(), msg.pose.pose.position
        with lock:
            g = truth_at(history, t)
        if g is not None:
            estimate[:] = [{"x": str(p.x), "y": str(p.y), "gx": g[0], "gy": g[1], "estimate_t": t}]

    with open(path, "w") as out:
        def on_diag(msg: DiagnosticArray) -> None:
            for st in msg.status:
                if "localization" not in st.name:
                    continue
                rec = {"t": rospy.get_time(), "level": int(st.level), "msg": st.message,
                       **{kv.key: kv.value for kv in st.values}}
                if estimate:
                    rec.update(estimate[0])
                out.write(json.dumps(rec) + "\n")
                out.flush()

        rospy.init_node("amcl_trace", anonymous=True)
        rospy.Subscriber("ground_truth/odom", Odometry, on_truth, queue_size=50)
        rospy.Subscriber("amcl_pose", PoseWithCovarianceStamped, on_pose, queue_size=10)
        rospy.Subscriber("diagnostics", DiagnosticArray, on_diag, queue_size=10)
        rospy.spin()


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out", help="JSON lines file")
    ap.add_argument("--summary", action="store_true", help="summarise a recorded file instead of recording")
    args = ap.parse_args()
    if args.summary:
        try:
            print("\n".join(summary(args.out)) or "nothing happened: no injection, no switch, never 0.15 m off")
        except (OSError, ValueError, KeyError) as exc:
            print(f"amcl_trace: {args.out}: {exc}", file=sys.stderr)
            return 2
        return 0
    record(args.out)
    return 0


if __name__ == "__main__":
    sys.exit(main())
