"""Waiting scaffolding shared by the rostest nodes (pure: no rospy import).

Every wait has a wall-clock deadline, so a test fails with a message naming
what it waited for instead of hanging when the simulation stalls, and it
holds whether the simulation runs faster or slower than real time.  Nodes
pass ``stop=rospy.is_shutdown`` so a shutdown ends the wait at once.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable


def wait_for(cond: Callable[[], object], timeout: float, what: str,
             stop: Callable[[], bool] | None = None, poll: float = 0.02) -> None:
    """Poll ``cond()`` every ``poll`` s until it holds; AssertionError after ``timeout`` s of wall time."""
    deadline = time.monotonic() + timeout
    while not cond():
        if time.monotonic() > deadline or (stop is not None and stop()):
            raise AssertionError(f"timed out after {timeout:.0f} s waiting for {what}")
        time.sleep(poll)


class SimClockWaits:
    """Mixin for test recorders that track the simulation clock (s) in ``self.clock`` under ``self.lock``.

    ``wall_timeout`` (s) bounds each wait; override :meth:`stopped` (e.g. with
    ``rospy.is_shutdown``) to end waits on shutdown.
    """

    lock: threading.Lock
    clock: float = -1.0
    wall_timeout: float = 120.0

    def stopped(self) -> bool:
        """True when waiting should end early (the node is shutting down)."""
        return False

    def now(self) -> float:
        """Latest simulation time (s) received, -1 before the first."""
        with self.lock:
            return self.clock

    def wait_for(self, cond: Callable[[], object], what: str) -> None:
        """Wait (wall-clock bounded) until ``cond()`` holds."""
        wait_for(cond, self.wall_timeout, what, stop=self.stopped, poll=0.01)

    def wait_until(self, t: float) -> None:
        """Wait until the simulation clock has reached ``t`` s."""
        self.wait_for(lambda: self.now() >= t, f"sim time {t:.2f}")
