"""Waiting scaffolding shared by the rostest nodes (pure: no rospy import), and reading a child's output.

Every wait has a wall-clock deadline, so a test fails with a message naming
what it waited for instead of hanging when the simulation stalls, and it
holds whether the simulation runs faster or slower than real time.  Nodes
pass ``stop=rospy.is_shutdown`` so a shutdown ends the wait at once.
"""
from __future__ import annotations

import math
import os
import signal
import subprocess
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


def run_in_group(cmd: list[str], timeout: float, env: dict[str, str] | None = None) -> tuple[int | None, str]:
    """Run ``cmd`` (stdin closed, stderr into stdout) in its own process group: (exit status, or None when
    it was still running after ``timeout`` s wall, its output).  The whole group is killed afterwards,
    whatever the command left behind, so a test never leaks it."""
    proc = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            start_new_session=True, env=env)
    rc: int | None = None
    try:
        out, _ = proc.communicate(timeout=timeout)
        rc = proc.returncode
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGKILL)
        out, _ = proc.communicate()
    finally:
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        proc.wait()
    return rc, out.decode(errors="replace")


def first_traceback(out: str, chars: int = 1500) -> str:
    """The first Python traceback in a process's output, up to ``chars`` characters from its first
    line (what a test's failure line should show, not the output's tail), or "" when there is none."""
    at = out.find("Traceback (most recent call last)")
    return "" if at < 0 else out[at:at + chars]


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


class SimRecorder(SimClockWaits):
    """A rostest recorder on the sim clock: stamped messages by key, and a velocity command
    re-sent on every /clock tick (so it flows at sim rate however fast the sim runs).

    Subclasses subscribe their topics to :meth:`add` and :meth:`on_clock`, and implement
    :meth:`publish_cmd` (they own the message types).
    """

    def __init__(self, keys: list[str]) -> None:
        self.lock = threading.Lock()
        self.clock = -1.0
        self.cmd: tuple[float, float] | None = None
        self.logs: dict[str, list] = {k: [] for k in keys}

    def publish_cmd(self, v: float, w: float) -> None:
        """Send (v m/s, w rad/s) to the robot."""
        raise NotImplementedError

    def add(self, key: str, msg) -> None:
        """Record a message with a std_msgs/Header under ``key`` by its stamp (s)."""
        with self.lock:
            self.logs[key].append((msg.header.stamp.to_sec(), msg))

    def on_clock(self, msg) -> None:
        """rosgraph_msgs/Clock callback: new sim time; re-send the current command."""
        with self.lock:
            self.clock = msg.clock.to_sec()
            cmd = self.cmd
        if cmd is not None:
            self.publish_cmd(*cmd)

    def set_cmd(self, cmd: tuple[float, float] | None) -> None:
        """Command (v, w) to keep sending, or None to send nothing."""
        with self.lock:
            self.cmd = cmd

    def between(self, key: str, t0: float, t1: float = math.inf) -> list:
        """Messages of ``key`` stamped in [t0, t1] s."""
        with self.lock:
            return [m for s, m in self.logs[key] if t0 <= s <= t1]

    def latest(self, key: str, after: float):
        """The newest message of ``key`` stamped after ``after`` s (waits for one)."""
        self.wait_for(lambda: bool(self.between(key, after)), f"{key} stamped after t={after:.2f}")
        return self.between(key, after)[-1]

    def at(self, key: str, t: float, window: float = 0.05):
        """The newest message of ``key`` stamped in [t - window, t] s.

        A topic's messages can arrive after /clock has passed their stamps, so
        this first waits for one stamped later than ``t``: every earlier one is
        in by then.  AssertionError, naming the gap, if none lies in the window.
        """
        self.latest(key, math.nextafter(t, math.inf))      # waits until the topic has passed t
        found = self.between(key, t - window, t)
        if not found:
            raise AssertionError(f"no {key} message stamped in [{t - window:.2f}, {t:.2f}] s")
        return found[-1]
