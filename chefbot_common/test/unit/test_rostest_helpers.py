"""SimRecorder.at: the message at a sim time, waiting for the topic to catch up with the clock."""
import threading
import time
from types import SimpleNamespace

import pytest

from chefbot_common.rostest_helpers import SimRecorder, first_traceback, run_in_group


def msg(stamp: float) -> SimpleNamespace:
    return SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(to_sec=lambda: stamp)), stamp=stamp)


class Rec(SimRecorder):
    wall_timeout = 2.0


def test_at_waits_for_the_topic_to_pass_the_time_then_gives_the_newest_in_the_window() -> None:
    r = Rec(["gt"])
    for s in (0.90, 0.96):
        r.add("gt", msg(s))
    # the clock is at 1.0 but gt has only reached 0.96; 0.99 arrives late
    threading.Timer(0.1, lambda: (r.add("gt", msg(0.99)), r.add("gt", msg(1.02)))).start()
    t0 = time.monotonic()
    assert r.at("gt", 1.0).stamp == 0.99
    assert time.monotonic() - t0 >= 0.09


def test_at_names_the_gap_when_no_message_lies_in_the_window() -> None:
    r = Rec(["gt"])
    for s in (0.5, 1.5):
        r.add("gt", msg(s))
    with pytest.raises(AssertionError, match=r"no gt message stamped in \[0.95, 1.00\]"):
        r.at("gt", 1.0)


def test_at_times_out_naming_the_topic_when_it_never_passes_the_time() -> None:
    r = Rec(["gt"])
    r.wall_timeout = 0.2
    r.add("gt", msg(0.99))
    with pytest.raises(AssertionError, match="gt stamped after t=1.00"):
        r.at("gt", 1.0)


def test_first_traceback_starts_at_the_traceback() -> None:
    out = "roslaunch noise\n" * 100 + "Traceback (most recent call last):\n  File x\nKeyError: 'a'\n" + "tail\n" * 50
    assert first_traceback(out).startswith("Traceback (most recent call last):\n  File x\nKeyError: 'a'")
    assert len(first_traceback(out, 40)) == 40
    assert first_traceback("all well\n") == ""


def test_run_in_group_returns_status_and_output_and_kills_what_hangs() -> None:
    assert run_in_group(["bash", "-c", "echo out; echo err >&2; exit 3"], 10.0) == (3, "out\nerr\n")
    t0 = time.monotonic()
    rc, out = run_in_group(["bash", "-c", "echo started; sleep 30"], 0.5)
    assert rc is None and out == "started\n" and time.monotonic() - t0 < 10.0
