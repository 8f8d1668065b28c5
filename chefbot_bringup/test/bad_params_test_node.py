#!/usr/bin/env python3
"""rostest node for bad_params.test: start each node with one bad parameter, expect a clean refusal."""
from __future__ import annotations

import os
import signal
import subprocess
import unittest

import rospkg
import rospy
import rostest

NODES = os.path.join(rospkg.RosPack().get_path("chefbot_bringup"), "nodes")
CASES = [
    ("twist_to_motors", "_rate:=-50.0", "~rate"),
    ("twist_to_motors", "_stop_distance:=0.9", "~stop_distance"),
    ("pid_velocity", "_Kp:=-1.0", "~Kp"),
    ("pid_velocity", "_wheel_type:=Float64", "~wheel_type"),
    ("pid_velocity", "_timeout_ticks:=0", "~timeout_ticks"),
    ("pid_velocity", "_side:=middle", "~side"),
    ("diff_tf", "_rate:=0.0", "~rate"),
    ("diff_tf", "_base_width:=-0.3", "~base_width"),
    ("diff_tf", "_ticks_meter_right:=-29708", "~ticks_meter_right"),
    ("depth_to_scan", "_scan_height:=0", "~scan_height"),
    ("depth_to_scan", "_range_min:=-1.0", "~range_min"),
    ("keyboard_teleop", "_key_timeout:=-1.0", "stdin is not a terminal"),   # the TTY check comes first
    ("cliff_guard", "_drop_threshold:=-0.1", "~drop_threshold"),
    ("cliff_guard", "_timeout:=0.0", "~timeout"),
    ("cliff_guard", "_topics:=[]", "~topics"),
    ("cliff_guard", "_rate:=0", "~rate"),
]


def run(node: str, arg: str, name: str) -> tuple[int, str]:
    """Run the node in its own process group; returns (exit code, output). Never leaves it running."""
    proc = subprocess.Popen([os.path.join(NODES, node), f"__name:={name}", arg], stdin=subprocess.DEVNULL,
                            stdout=subprocess.PIPE, stderr=subprocess.STDOUT, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=30.0)
        return proc.returncode, out.decode(errors="replace")
    except subprocess.TimeoutExpired:
        return -1, "still running after 30 s (the bad value was accepted)"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()


class TestBadParams(unittest.TestCase):
    def test_nodes_reject_bad_params(self) -> None:
        # One test with a list of problems: rosunit's XML runner does not report subTest failures.
        problems = []
        for k, (node, arg, expect) in enumerate(CASES):
            rc, out = run(node, arg, f"bad_{node}_{k}")
            if rc != 2 or expect not in out:
                problems.append(f"{node} {arg}: exit {rc}, output:\n{out[-600:]}")
        self.assertEqual(problems, [], "\n\n".join(problems))


if __name__ == "__main__":
    rospy.init_node("bad_params_check", disable_signals=True)
    rostest.rosrun("chefbot_bringup", "bad_params", TestBadParams)
