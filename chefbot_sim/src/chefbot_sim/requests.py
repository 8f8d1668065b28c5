"""Requests from ROS callback threads, run by the simulator's own loop (pure: threading only).

pybullet is not thread-safe: every callback puts a callable here, and the
sim loop runs them between physics batches.
"""
from __future__ import annotations

import queue
import threading
from collections.abc import Callable


class SimRequests:
    """A queue of callables run by the sim loop; :meth:`call` also waits for the result."""

    def __init__(self) -> None:
        self._q: queue.Queue[Callable[[], None]] = queue.Queue()

    def put(self, fn: Callable[[], None]) -> None:
        """Run ``fn`` at the sim loop's next turn."""
        self._q.put(fn)

    def put_guarded(self, fn: Callable[[], None], what: str, errors: tuple[type[BaseException], ...],
                    log: Callable[[str], None]) -> None:
        """Run ``fn``; a failure of the kinds ``errors`` is logged as '``what`` rejected: ...' (the sim goes on)."""
        def run() -> None:
            try:
                fn()
            except errors as e:
                log(f"chefbot_sim: {what} rejected: {e}")
        self._q.put(run)

    def call(self, fn: Callable[[], None], stop: Callable[[], bool], poll: float = 0.1) -> None:
        """Run ``fn`` in the sim loop and wait until it has run (or ``stop()`` turns true)."""
        done = threading.Event()

        def run() -> None:
            try:
                fn()
            finally:
                done.set()
        self._q.put(run)
        while not done.wait(poll):
            if stop():
                break

    def run_pending(self) -> None:
        """Run every queued request (sim loop only)."""
        while True:
            try:
                fn = self._q.get_nowait()
            except queue.Empty:
                return
            fn()
