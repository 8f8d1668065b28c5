"""Give the C heap's free pages back to the system now and then (glibc's ``malloc_trim``).

A rospy node runs its callbacks on many threads (one per connection, timers, services), and glibc
gives each thread that allocates its own malloc arena (up to 8 per core).  numpy's temporary arrays
of a particle filter or a scan matcher are freed at once, but the pages they leave free in an arena
stay with the process, so its memory climbs for a long time before it levels off (the fleet soak's
amcl, docs/soak.md).  ``malloc_trim(0)`` returns the free pages of every arena (glibc >= 2.8)
without moving live memory.

:func:`start_trimming` runs it every ``CHEFBOT_HEAP_TRIM_S`` s of wall time (default 30; 0 turns it
off) on a daemon thread; ``quiet_interrupt.run`` starts it for every node.  Where the C library is
not glibc (no ``malloc_trim``) nothing is done.  Pure: no rospy.
"""
from __future__ import annotations

import ctypes
import ctypes.util
import os
import threading

ENV = "CHEFBOT_HEAP_TRIM_S"
DEFAULT_PERIOD_S = 30.0
_libc_trim = None


def _trim_function():
    """glibc's ``malloc_trim`` (cached), or None where the C library has none."""
    global _libc_trim
    if _libc_trim is None:
        try:
            fn = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6").malloc_trim
            fn.argtypes, fn.restype = [ctypes.c_size_t], ctypes.c_int
            _libc_trim = fn
        except (OSError, AttributeError):
            _libc_trim = False
    return _libc_trim or None


def trim() -> bool:
    """Return the heap's free pages to the system; True if memory was released, False if none was or
    the C library cannot (not glibc)."""
    fn = _trim_function()
    return bool(fn(0)) if fn is not None else False


def period(raw: str | None) -> float:
    """The trimming period (s) from ``CHEFBOT_HEAP_TRIM_S``: unset or blank: the default; 0 or less:
    off (0.0).  ValueError names the variable for anything that is not a number."""
    if raw is None or not raw.strip():
        return DEFAULT_PERIOD_S
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"{ENV} must be a number of seconds (0: off), got {raw!r}") from None
    if value != value or value in (float("inf"), float("-inf")):
        raise ValueError(f"{ENV} must be a finite number of seconds (0: off), got {raw!r}")
    return max(value, 0.0)


def start_trimming(period_s: float | None = None) -> threading.Thread | None:
    """Trim every ``period_s`` s of wall time (default: ``CHEFBOT_HEAP_TRIM_S``) on a daemon thread,
    the first time after one period; None (nothing started) when off or not glibc.  A bad
    ``CHEFBOT_HEAP_TRIM_S`` raises ValueError."""
    every = period(os.environ.get(ENV)) if period_s is None else period_s
    if every <= 0 or _trim_function() is None:
        return None
    stop = threading.Event()

    def loop() -> None:
        while not stop.wait(every):
            trim()

    th = threading.Thread(target=loop, name="heap trim", daemon=True)
    th.stop = stop           # type: ignore[attr-defined]  -- tests end it
    th.start()
    return th
