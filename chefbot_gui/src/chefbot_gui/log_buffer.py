"""The Console's model: a bounded log buffer with a severity/node/text filter and pause.

Pure (no rospy, no Qt): entries are plain :class:`LogEntry` values built by the
ROS bridge from ``rosgraph_msgs/Log``; time is float seconds.  The buffer keeps
the newest ``capacity`` entries (the oldest are dropped) and a *view*: the
entries that pass the filter, updated incrementally so a table model can insert
and remove rows instead of resetting (selection and scroll position survive).
"""
from __future__ import annotations

import time
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

# rosgraph_msgs/Log level constants (bit values, as on the wire)
DEBUG, INFO, WARN, ERROR, FATAL = 1, 2, 4, 8, 16
SEVERITY_NAMES = {DEBUG: "Debug", INFO: "Info", WARN: "Warn", ERROR: "Error", FATAL: "Fatal"}
ALL_SEVERITIES = frozenset(SEVERITY_NAMES)
DEFAULT_CAPACITY = 10_000  # lines kept; about 3 MB of typical log text


def severity_name(level: int) -> str:
    """``Info`` for 2, … ; unknown levels read ``level 3`` (never raises)."""
    return SEVERITY_NAMES.get(level, f"level {level}")


def fmt_stamp(stamp_s: float) -> str:
    """A log time for people: local ``HH:MM:SS.mmm`` for wall-clock stamps, seconds for sim time.

    Stamps before 2001 (< 1e9 s) are simulation time (``/use_sim_time``), shown
    as ``123.456 s``; non-finite or negative stamps read ``?``.
    """
    if not (stamp_s >= 0.0) or stamp_s == float("inf"):
        return "?"
    if stamp_s < 1e9:
        return f"{stamp_s:.3f} s"
    lt = time.localtime(stamp_s)
    return time.strftime("%H:%M:%S", lt) + f".{int((stamp_s % 1.0) * 1000):03d}"


@dataclass(frozen=True)
class LogEntry:
    """One ``rosgraph_msgs/Log`` line.  ``stamp``: s (header stamp); ``level``: bit value."""

    stamp: float
    level: int
    node: str
    message: str
    file: str = ""
    function: str = ""
    line: int = 0
    seq: int = 0  # set by the buffer: arrival order, unique per buffer

    @property
    def location(self) -> str:
        """``file:function:line`` as rqt_console shows it (empty parts left out)."""
        parts = [self.file, self.function, str(self.line) if self.line else ""]
        return ":".join(p for p in parts if p)


@dataclass(frozen=True)
class LogFilter:
    """Which entries the view shows.

    ``severities``: levels shown; ``node``: case-insensitive substring of the
    node name (empty = all); ``text``: case-insensitive substring of the message
    (empty = all).
    """

    severities: frozenset[int] = ALL_SEVERITIES
    node: str = ""
    text: str = ""

    def accepts(self, e: LogEntry) -> bool:
        """Does ``e`` pass this filter?  Unknown levels pass when every severity is shown."""
        if e.level in SEVERITY_NAMES:
            if e.level not in self.severities:
                return False
        elif self.severities != ALL_SEVERITIES:
            return False
        if self.node and self.node.lower() not in e.node.lower():
            return False
        return not self.text or self.text.lower() in e.message.lower()


@dataclass(frozen=True)
class ViewChange:
    """How the view changed: drop ``removed`` rows at the front, then append ``added``
    rows at the end; or, if ``reset``, re-read the whole view."""

    removed: int = 0
    added: int = 0
    reset: bool = False


@dataclass
class LogBuffer:
    """The newest ``capacity`` log entries and the filtered view of them.

    While paused, new entries are still stored (bounded) but the view stays as it
    was; :meth:`resume` rebuilds it, so nothing that arrived meanwhile is lost
    (unless more than ``capacity`` arrived).
    """

    capacity: int = DEFAULT_CAPACITY
    filter: LogFilter = field(default_factory=LogFilter)
    paused: bool = False
    received: int = 0   # entries ever added (since the last clear)
    dropped: int = 0    # entries dropped for capacity (since the last clear)
    _entries: deque[LogEntry] = field(init=False, repr=False)
    _view: deque[LogEntry] = field(init=False, repr=False)
    _next_seq: int = field(default=0, init=False, repr=False)

    def __post_init__(self) -> None:
        if self.capacity < 1:
            raise ValueError(f"log buffer capacity must be >= 1 line, got {self.capacity}")
        self._entries = deque(maxlen=self.capacity)
        self._view = deque()

    # ------------------------------------------------------------------ reading
    @property
    def view(self) -> deque[LogEntry]:
        """The entries shown, oldest first (do not modify)."""
        return self._view

    def __len__(self) -> int:
        return len(self._entries)

    def status(self) -> str:
        """``120 of 5000 lines shown (300 dropped, paused)``-style summary for a status bar."""
        extra = []
        if self.dropped:
            extra.append(f"{self.dropped} oldest dropped, keeping {self.capacity}")
        if self.paused:
            extra.append(f"paused, {self._pending()} new")
        tail = f" ({'; '.join(extra)})" if extra else ""
        return f"{len(self._view)} of {len(self._entries)} lines shown{tail}"

    def _pending(self) -> int:
        last = self._view[-1].seq if self._view else -1
        return sum(1 for e in self._entries if e.seq > last)

    # ------------------------------------------------------------------ changing
    def add(self, entries: Iterable[LogEntry]) -> ViewChange:
        """Store new entries (in arrival order); returns how the view changed."""
        batch = []
        for e in entries:
            batch.append(LogEntry(e.stamp, e.level, e.node, e.message, e.file, e.function, e.line,
                                  seq=self._next_seq))
            self._next_seq += 1
        if not batch:
            return ViewChange()
        self.received += len(batch)
        over = max(0, len(self._entries) + len(batch) - self.capacity)
        self.dropped += over
        self._entries.extend(batch)
        if self.paused:
            return ViewChange()
        if len(batch) >= self.capacity:  # the whole view turned over: cheaper to reset
            self._rebuild()
            return ViewChange(reset=True)
        # fewer than capacity new entries: only pre-existing entries were dropped, oldest first
        oldest = self._entries[0].seq
        removed = 0
        while self._view and self._view[0].seq < oldest:
            self._view.popleft()
            removed += 1
        shown = [e for e in batch if self.filter.accepts(e)]
        self._view.extend(shown)
        return ViewChange(removed=removed, added=len(shown))

    def set_filter(self, f: LogFilter) -> ViewChange:
        """Show only what ``f`` accepts (from everything stored)."""
        self.filter = f
        if self.paused:
            return ViewChange()
        self._rebuild()
        return ViewChange(reset=True)

    def pause(self) -> None:
        """Freeze the view; new entries are kept for :meth:`resume`."""
        self.paused = True

    def resume(self) -> ViewChange:
        """Unfreeze: the view shows everything stored that passes the filter."""
        self.paused = False
        self._rebuild()
        return ViewChange(reset=True)

    def clear(self) -> ViewChange:
        """Forget every entry (and the counters)."""
        self._entries.clear()
        self._view.clear()
        self.received = self.dropped = 0
        return ViewChange(reset=True)

    def _rebuild(self) -> None:
        self._view = deque(e for e in self._entries if self.filter.accepts(e))
