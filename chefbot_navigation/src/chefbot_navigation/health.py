"""Health of background work (pure): error counts and throttled reporting of periodic tasks,
and a thread-safe queue that lets sensor callbacks hand scans over without the planner's lock.

A periodic thread that raises must not die silently (issue 10: a MemoryError ended the costmap
publisher for good).  :class:`TaskHealth` counts calls and failures, says when a failure should be
logged (at most once per ``log_period`` s, with the number of failures since), and summarises itself
as a diagnostic level and message (``diagnostic_msgs/DiagnosticStatus`` levels: 0 OK, 1 WARN, 2 ERROR).
"""
from __future__ import annotations

import threading
from collections import deque
from dataclasses import dataclass, field
from typing import Any

OK, WARN, ERROR = 0, 1, 2


@dataclass
class TaskHealth:
    """Counters of one periodic task; times are float seconds of any clock."""

    name: str
    log_period: float = 10.0        # s, at most one log line per period
    recent_window: float = 30.0     # s, an error this recent makes the task ERROR, older -> WARN
    calls: int = 0
    errors: int = 0
    last_error: str = ""
    last_error_time: float | None = None
    _last_log: float | None = None
    _unlogged: int = 0
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False)

    def ok(self) -> None:
        """One call finished normally."""
        with self._lock:
            self.calls += 1

    def failed(self, exc: BaseException, t: float) -> str | None:
        """One call raised ``exc`` at time ``t`` (s): the line to log now, or None (throttled)."""
        with self._lock:
            self.calls += 1
            self.errors += 1
            self.last_error = f"{type(exc).__name__}: {exc}"
            self.last_error_time = t
            self._unlogged += 1
            if self._last_log is not None and 0.0 <= t - self._last_log < self.log_period:
                return None
            n, self._unlogged, self._last_log = self._unlogged, 0, t
        more = f" ({n} failures since the last report, {self.errors} in all)" if n > 1 else ""
        return f"{self.name}: {self.last_error}{more}; the task keeps running"

    def status(self, t: float) -> tuple[int, str, dict[str, Any]]:
        """(level, message, key values) for a diagnostic status at time ``t`` (s)."""
        with self._lock:
            values = {"calls": self.calls, "errors": self.errors, "last error": self.last_error or "-"}
            if not self.errors:
                return OK, "running", values
            age = t - self.last_error_time
            level = ERROR if age <= self.recent_window else WARN
            return level, f"{self.errors} of {self.calls} calls failed; last {age:.0f} s ago: {self.last_error}", values


class PendingQueue:
    """Items handed from callbacks to the thread that owns the data, under a lock of its own.

    ``put`` never waits on the consumer's (possibly long) work; when more than ``maxlen`` items wait,
    the oldest are dropped and counted (``dropped``).
    """

    def __init__(self, maxlen: int = 20) -> None:
        if maxlen < 1:
            raise ValueError(f"maxlen must be >= 1, got {maxlen}")
        self._items: deque = deque()
        self._maxlen = maxlen
        self._lock = threading.Lock()
        self.dropped = 0

    def put(self, item: Any) -> None:
        """Queue ``item`` (constant time; never blocks on the consumer)."""
        with self._lock:
            self._items.append(item)
            while len(self._items) > self._maxlen:
                self._items.popleft()
                self.dropped += 1

    def drain(self) -> list:
        """Every waiting item, oldest first; the queue is empty afterwards."""
        with self._lock:
            items = list(self._items)
            self._items.clear()
        return items

    def clear(self) -> None:
        """Forget the waiting items."""
        with self._lock:
            self._items.clear()

    def __len__(self) -> int:
        with self._lock:
            return len(self._items)
