"""A node's periodic loop that stops cleanly on shutdown (ROS side: imports rospy)."""
from __future__ import annotations

import threading
from collections.abc import Callable

import rospy


class LockedTimer:
    """Calls ``fn()`` at ``rate_hz`` (a rospy.Timer) holding ``lock``, and never again once the node
    shuts down: :meth:`stop` is registered with rospy.on_shutdown, which runs before rospy closes the
    publishers, so Ctrl-C never gives "publish() to a closed topic".  The node's callbacks that
    publish take the same ``lock`` and check :attr:`stopping` too."""

    def __init__(self, rate_hz: float, fn: Callable[[], None], lock: threading.Lock) -> None:
        self.fn, self.lock = fn, lock
        self.stopping = threading.Event()
        self.timer = rospy.Timer(rospy.Duration(1.0 / rate_hz), self._tick)
        rospy.on_shutdown(self.stop)

    def _tick(self, _event) -> None:
        with self.lock:   # publishing under the lock: nothing goes out once stop() has run
            if not self.stopping.is_set():
                self.fn()

    def stop(self) -> None:
        """Stop the loop for good (waits for a running tick to finish)."""
        with self.lock:
            self.stopping.set()
            self.timer.shutdown()
