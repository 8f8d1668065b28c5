#!/usr/bin/env python3
"""Record amcl's /diagnostics next to the simulator's ground truth, one JSON line per status (a
developer's tool for localization failures; the ground truth is the TEST ORACLE, sim only).

    ROS_MASTER_URI=... python tools/amcl_trace.py OUT.jsonl      # until Ctrl-C
    python tools/amcl_trace.py --summary OUT.jsonl               # what happened, afterwards

Each line: sim time ``t``, the status ``level`` and ``msg``, every value amcl reports (particles,
mean_beam_fit, w_slow, w_fast, injected_last_resample, estimate_switches, x, y, yaw, std_xy ...)
and the ground truth ``gx``, ``gy``.  The summary prints the lines where something happened:
particles injected, the estimate switching cluster, or the estimate over 0.15 m off.  This is how
the cafe's home-leg failure of 2026-11-23 was traced to recovery injection (chefbot_navigation
README, amcl "recovery").
"""
from __future__ import annotations

import argparse
import json
import math
import sys


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


def record(path: str) -> None:
    import rospy
    from diagnostic_msgs.msg import DiagnosticArray
    from nav_msgs.msg import Odometry

    truth: list[Odometry] = []

    def on_truth(msg: Odometry) -> None:
        truth[:] = [msg]

    with open(path, "w") as out:
        def on_diag(msg: DiagnosticArray) -> None:
            for st in msg.status:
                if "localization" not in st.name:
                    continue
                rec = {"t": rospy.get_time(), "level": int(st.level), "msg": st.message,
                       **{kv.key: kv.value for kv in st.values}}
                if truth:
                    p = truth[0].pose.pose.position
                    rec.update(gx=p.x, gy=p.y)
                out.write(json.dumps(rec) + "\n")
                out.flush()

        rospy.init_node("amcl_trace", anonymous=True)
        rospy.Subscriber("ground_truth/odom", Odometry, on_truth, queue_size=1)
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
