"""The Topic Monitor's model: rate and bandwidth over a sliding window, and the topic list.

Pure (no rospy, no Qt); times are float seconds from any monotonic clock.

Rate is measured as ``rostopic hz`` does: the mean interval between the
arrivals kept in the window, ``rate = (n - 1) / (t_last - t_first)``.
Bandwidth as ``rostopic bw`` does: the bytes in the window divided by the
time from the first of them to now.  The window holds the arrivals of the last
``window_s`` seconds, at most ``max_samples`` of them.
"""
from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass, field

DEFAULT_WINDOW_S = 5.0
DEFAULT_MAX_SAMPLES = 1000
STALE_PERIODS = 3.0   # no arrival for this many mean periods (and ≥ STALE_MIN_S) → stale
STALE_MIN_S = 1.0


@dataclass(frozen=True)
class Stats:
    """A snapshot of one topic's traffic.

    ``rate_hz`` (None: fewer than two arrivals in the window), ``bandwidth_bps``
    (B/s; None: nothing in the window), ``count``: arrivals in the window,
    ``total``: arrivals ever, ``mean_size``/``max_size``: bytes per message in
    the window, ``age_s``: s since the last arrival (None: never), ``stale``: no
    arrival for ``STALE_PERIODS`` mean periods.
    """

    rate_hz: float | None = None
    bandwidth_bps: float | None = None
    count: int = 0
    total: int = 0
    mean_size: float | None = None
    max_size: int | None = None
    age_s: float | None = None
    stale: bool = False


@dataclass
class WindowStats:
    """Arrival times and sizes of one topic's messages over a sliding window."""

    window_s: float = DEFAULT_WINDOW_S
    max_samples: int = DEFAULT_MAX_SAMPLES
    total: int = 0
    _samples: deque[tuple[float, int]] = field(default_factory=deque, repr=False)
    _last: float | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        if not (math.isfinite(self.window_s) and self.window_s > 0):
            raise ValueError(f"stats window must be > 0 s, got {self.window_s}")
        if self.max_samples < 2:
            raise ValueError(f"stats window must hold >= 2 samples, got {self.max_samples}")

    def add(self, t: float, nbytes: int) -> None:
        """One message of ``nbytes`` bytes arrived at ``t`` (s)."""
        self._samples.append((t, int(nbytes)))
        self._last = t
        self.total += 1
        while len(self._samples) > self.max_samples:
            self._samples.popleft()

    def reset(self) -> None:
        """Forget every sample (e.g. after re-subscribing)."""
        self._samples.clear()
        self._last = None
        self.total = 0

    def snapshot(self, now: float) -> Stats:
        """The statistics of the arrivals within ``window_s`` before ``now`` (s)."""
        s = self._samples
        while s and s[0][0] < now - self.window_s:
            s.popleft()
        age = None if self._last is None else max(0.0, now - self._last)
        n = len(s)
        if n == 0:
            return Stats(total=self.total, age_s=age, stale=self._last is not None)
        sizes = [b for _t, b in s]
        t0, t1 = s[0][0], s[-1][0]
        rate = (n - 1) / (t1 - t0) if n >= 2 and t1 > t0 else None
        span = now - t0
        bw = sum(sizes) / span if span > 0 else None
        stale = False
        if rate is not None and age is not None:
            stale = age > max(STALE_PERIODS / rate, STALE_MIN_S)
        return Stats(rate_hz=rate, bandwidth_bps=bw, count=n, total=self.total,
                     mean_size=sum(sizes) / n, max_size=max(sizes), age_s=age, stale=stale)


def fmt_rate(st: Stats) -> str:
    """``10.0 Hz``, ``—`` without enough data; ``(stale)`` appended when messages stopped."""
    if st.rate_hz is None:
        return "—" if st.total < 2 else "— (stale)"
    return f"{st.rate_hz:.3g} Hz" + (" (stale)" if st.stale else "")


def fmt_bandwidth(bps: float | None) -> str:
    """``512 B/s``, ``12.3 KB/s``, ``4.56 MB/s`` (1 KB = 1000 B, as rostopic bw); ``—`` for None."""
    if bps is None:
        return "—"
    for unit, scale in (("MB/s", 1e6), ("KB/s", 1e3)):
        if bps >= scale:
            return f"{bps / scale:.3g} {unit}"
    return f"{bps:.0f} B/s"


@dataclass
class TopicRow:
    """One row of the topic list: ``published`` is False once the master stops listing it."""

    name: str
    type: str
    ticked: bool = False
    published: bool = True


class TopicList:
    """Every topic the master lists, in name order, plus ticked topics that disappeared.

    Unticked topics that disappear from the master are dropped; ticked ones stay
    (marked not published) so the user sees what happened and their subscription
    picks the topic up again if a publisher returns.
    """

    def __init__(self) -> None:
        self.rows: dict[str, TopicRow] = {}

    def update(self, listed: Iterable[tuple[str, str]]) -> list[str]:
        """Merge the master's ``(name, type)`` list; returns the names whose type changed.

        A ticked topic whose type changed must be re-subscribed by the caller.
        """
        listed = dict(listed)
        changed = []
        for name in list(self.rows):
            row = self.rows[name]
            if name not in listed:
                if row.ticked:
                    row.published = False
                else:
                    del self.rows[name]
        for name, typ in listed.items():
            row = self.rows.get(name)
            if row is None:
                self.rows[name] = TopicRow(name, typ)
                continue
            row.published = True
            if row.type != typ:
                row.type = typ
                changed.append(name)
        self.rows = dict(sorted(self.rows.items()))
        return changed

    def names(self) -> list[str]:
        """Topic names in display order."""
        return list(self.rows)

    def of_type(self, typ: str) -> list[str]:
        """Published topics of message type ``typ`` (e.g. ``sensor_msgs/Image``), sorted."""
        return [r.name for r in self.rows.values() if r.type == typ and r.published]

    def set_ticked(self, name: str, ticked: bool) -> TopicRow:
        """Tick or untick ``name``; an unticked topic gone from the master is dropped."""
        row = self.rows[name]
        row.ticked = ticked
        if not ticked and not row.published:
            del self.rows[name]
        return row
