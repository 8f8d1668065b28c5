"""The Console's log buffer: bounded, filtered, pausable (no ROS, no Qt)."""
from __future__ import annotations

import pytest

from chefbot_gui.log_buffer import (
    DEBUG,
    ERROR,
    FATAL,
    INFO,
    WARN,
    LogBuffer,
    LogEntry,
    LogFilter,
    ViewChange,
    fmt_stamp,
    severity_name,
)


def e(msg: str, level: int = INFO, node: str = "/talker") -> LogEntry:
    return LogEntry(stamp=100.0, level=level, node=node, message=msg, file="f.py", function="fn", line=3)


def messages(buf: LogBuffer) -> list[str]:
    return [x.message for x in buf.view]


def test_oldest_entries_are_dropped_at_capacity_and_the_view_follows() -> None:
    buf = LogBuffer(capacity=3)
    assert buf.add([e("a"), e("b")]) == ViewChange(removed=0, added=2)
    assert buf.add([e("c"), e("d")]) == ViewChange(removed=1, added=2)
    assert messages(buf) == ["b", "c", "d"]
    assert (len(buf), buf.received, buf.dropped) == (3, 4, 1)
    assert "1 oldest dropped" in buf.status()


def test_a_batch_larger_than_the_capacity_resets_the_view() -> None:
    buf = LogBuffer(capacity=3)
    buf.add([e("a")])
    assert buf.add([e(str(i)) for i in range(5)]).reset
    assert messages(buf) == ["2", "3", "4"]


def test_filtered_out_entries_are_dropped_from_the_view_only_if_shown() -> None:
    buf = LogBuffer(capacity=3, filter=LogFilter(severities=frozenset({ERROR})))
    buf.add([e("x", ERROR), e("i1"), e("i2")])
    assert messages(buf) == ["x"]
    assert buf.add([e("i3")]) == ViewChange(removed=1, added=0)  # "x" fell out of the buffer
    assert messages(buf) == []


def test_severity_node_and_text_filters() -> None:
    buf = LogBuffer()
    buf.add([e("hello", DEBUG), e("warned", WARN, "/amcl"), e("broke", ERROR, "/move_base"),
             e("dead", FATAL, "/AMCL_2"), e("odd level", 3)])
    assert buf.set_filter(LogFilter(severities=frozenset({WARN, ERROR, FATAL}))).reset
    assert messages(buf) == ["warned", "broke", "dead"]  # unknown level hidden once a severity is off
    buf.set_filter(LogFilter(node="amcl"))
    assert messages(buf) == ["warned", "dead"]  # case-insensitive substring
    buf.set_filter(LogFilter(text="BROKE"))
    assert messages(buf) == ["broke"]
    buf.set_filter(LogFilter())
    assert len(buf.view) == 5
    buf.add([e("new warn", WARN, "/amcl")])
    assert messages(buf)[-1] == "new warn"


def test_pause_freezes_the_view_and_resume_shows_what_arrived() -> None:
    buf = LogBuffer(capacity=10)
    buf.add([e("a")])
    buf.pause()
    assert buf.add([e("b"), e("c")]) == ViewChange()
    assert messages(buf) == ["a"]
    assert "paused, 2 new" in buf.status()
    buf.set_filter(LogFilter(text="c"))  # no effect on the frozen view
    assert messages(buf) == ["a"]
    assert buf.resume().reset
    assert messages(buf) == ["c"]


def test_clear_forgets_everything() -> None:
    buf = LogBuffer(capacity=2)
    buf.add([e("a"), e("b"), e("c")])
    assert buf.clear().reset
    assert (len(buf), len(buf.view), buf.received, buf.dropped) == (0, 0, 0, 0)
    buf.add([e("d")])
    assert messages(buf) == ["d"]


def test_sequence_numbers_and_location() -> None:
    buf = LogBuffer()
    buf.add([e("a"), e("b")])
    assert [x.seq for x in buf.view] == [0, 1]
    assert buf.view[0].location == "f.py:fn:3"
    assert LogEntry(0.0, INFO, "/n", "m").location == ""


def test_bad_capacity_is_rejected_with_its_name() -> None:
    with pytest.raises(ValueError, match="capacity"):
        LogBuffer(capacity=0)


def test_texts() -> None:
    assert severity_name(WARN) == "Warn"
    assert severity_name(3) == "level 3"
    assert fmt_stamp(12.3456) == "12.346 s"  # sim time
    assert fmt_stamp(float("nan")) == "?"
    assert fmt_stamp(-1.0) == "?"
    assert len(fmt_stamp(1.7e9 + 0.25)) == len("HH:MM:SS.250") and fmt_stamp(1.7e9 + 0.25).endswith(".250")
