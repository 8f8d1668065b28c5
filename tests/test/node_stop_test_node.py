#!/usr/bin/env python3
"""rostest node for node_stop.test: a node stopped (SIGINT) while it starts exits by itself, quietly.

roslaunch stops a whole launch with SIGINT when a required node dies (map_server on a corrupt map),
and a sibling may be anywhere in its startup.  Two moments of rospy's own startup are made to
happen on purpose, each in a small node run as a child process against this test's master:

* inside ``rospy.init_node`` while it registers (``start_node`` wrapped to signal itself first):
  rospy raises ``ROSInitException("init_node interrupted ...")``;
* while the main thread is inside a call to the master (the master proxy's lock held, as during
  ``rospy.get_param``): rospy's signal handler needs that lock and the node deadlocks.

Each child runs once ending with ``quiet_interrupt.run(main)`` (ours: must end, status as stated,
no traceback) and once with ``sys.exit(main())`` (plain rospy: the traceback or the hang, which
shows the case really reaches the fault).  Stopping during imports needs no master: chefbot_common's
unit tests.
"""
from __future__ import annotations

import os
import sys
import tempfile
import unittest

import rospy
import rostest

from chefbot_common.rostest_helpers import first_traceback, run_in_group

PKG = "chefbot_tests"
TIMEOUT = 20.0    # s wall: a child that has not ended by then is hung
PLAIN_HANG = 6.0  # s wall given to the plain-rospy deadlock before it counts as hung

HEAD = """\
from chefbot_common import quiet_interrupt
import os, signal, sys, time
import rospy
"""
# inside init_node: wrap start_node (registration with the master) to be signalled first
IN_INIT = """
import rospy.impl.init
_start = rospy.impl.init.start_node
def start_node(*args, **kwargs):
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(0.05)     # the handler runs here, on the main thread
    return _start(*args, **kwargs)
rospy.impl.init.start_node = start_node

def main():
    rospy.init_node("stopped_in_init", anonymous=True)
    print("NOT REACHED: init_node returned", flush=True)
    rospy.spin()
    return 0
"""
# inside a call to the master: hold the proxy's lock (as _LockedServerProxy does during the call)
IN_MASTER_CALL = """
def main():
    rospy.init_node("stopped_in_master_call", anonymous=True)
    proxy = rospy.get_master().target    # the _LockedServerProxy that get_param and unregistering use
    with proxy._lock:
        os.kill(os.getpid(), signal.SIGINT)
        time.sleep(0.3)  # the handler runs here, on the main thread, with the lock held
    print("lock released", flush=True)
    rospy.spin()
    print("spin returned", flush=True)
    return 0
"""
RUN = "\nquiet_interrupt.run(main)\n"
PLAIN = "\nquiet_interrupt.restore()\nsys.exit(main())\n"


def run_child(source: str, timeout: float = TIMEOUT) -> tuple[int | None, str]:
    """Run ``source`` as a Python node (run_in_group); (exit status or None if hung, output)."""
    with tempfile.NamedTemporaryFile("w", suffix=".py", prefix="node_stop_", delete=False) as f:
        f.write(source)
    try:
        return run_in_group([sys.executable, f.name], timeout)
    finally:
        os.unlink(f.name)


class NodeStopTest(unittest.TestCase):
    def check_quiet(self, what: str, rc: int | None, out: str, status: int) -> None:
        print(f"[figure] {what}, under quiet_interrupt.run: exit {rc}", flush=True)
        self.assertIsNotNone(rc, f"{what}: still running {TIMEOUT:.0f} s after SIGINT:\n{out[-1500:]}")
        self.assertFalse(first_traceback(out), f"{what}: a traceback: {first_traceback(out)}")
        self.assertEqual(rc, status, f"{what}: exit {rc}, expected {status}:\n{out[-1500:]}")

    def test_a_sigint_inside_init_node(self) -> None:
        rc, out = run_child(HEAD + IN_INIT + RUN)
        self.check_quiet("SIGINT inside init_node", rc, out, 1)
        self.assertNotIn("NOT REACHED", out)
        rc, out = run_child(HEAD + IN_INIT + PLAIN)
        print(f"[figure] SIGINT inside init_node, plain rospy: exit {rc}, "
              f"{'ROSInitException traceback' if 'ROSInitException' in out else 'no traceback'}", flush=True)
        self.assertIn("init_node interrupted before it could complete", out,
                      f"the case no longer reaches rospy's fault:\n{out[-1500:]}")

    def test_b_sigint_inside_a_master_call(self) -> None:
        rc, out = run_child(HEAD + IN_MASTER_CALL + RUN)
        self.check_quiet("SIGINT inside a call to the master", rc, out, 0)
        self.assertIn("spin returned", out, f"rospy.spin() did not return:\n{out[-1500:]}")
        rc, out = run_child(HEAD + IN_MASTER_CALL + PLAIN, PLAIN_HANG)
        print(f"[figure] SIGINT inside a call to the master, plain rospy: "
              f"{'hung' if rc is None else f'exit {rc}'} after {PLAIN_HANG:.0f} s", flush=True)
        self.assertIsNone(rc, f"plain rospy no longer deadlocks here (the case misses the fault):\n{out[-1500:]}")


if __name__ == "__main__":
    rospy.init_node("node_stop_test", disable_signals=True)
    rostest.rosrun(PKG, "node_stop", NodeStopTest)
