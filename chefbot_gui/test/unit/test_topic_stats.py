"""Rate/bandwidth window statistics and the topic list (no ROS, no Qt; injected times)."""
from __future__ import annotations

import pytest

from chefbot_gui.topic_stats import Stats, TopicList, WindowStats, fmt_bandwidth, fmt_rate


def feed(ws: WindowStats, hz: float, n: int, size: int, t0: float = 0.0) -> float:
    for i in range(n):
        ws.add(t0 + i / hz, size)
    return t0 + (n - 1) / hz


def test_rate_and_bandwidth_of_a_steady_stream() -> None:
    ws = WindowStats(window_s=5.0)
    t = feed(ws, 10.0, 30, 100)
    st = ws.snapshot(t)
    assert st.rate_hz == pytest.approx(10.0)
    assert st.bandwidth_bps == pytest.approx(30 * 100 / 2.9)
    assert (st.count, st.total, st.mean_size, st.max_size, st.stale) == (30, 30, 100, 100, False)


def test_the_window_slides_and_bounds_the_samples() -> None:
    ws = WindowStats(window_s=1.0, max_samples=5)
    t = feed(ws, 10.0, 50, 10)
    st = ws.snapshot(t)
    assert st.count == 5 and st.total == 50
    assert st.rate_hz == pytest.approx(10.0)
    ws2 = WindowStats(window_s=1.0)
    t = feed(ws2, 100.0, 300, 10)
    assert ws2.snapshot(t).count in (100, 101)  # arrivals within the last 1 s (edge: float rounding)


def test_a_stream_that_stops_goes_stale_then_empty() -> None:
    ws = WindowStats(window_s=5.0)
    t = feed(ws, 10.0, 20, 8)
    st = ws.snapshot(t + 2.0)
    assert st.stale and st.rate_hz == pytest.approx(10.0) and st.age_s == pytest.approx(2.0)
    assert fmt_rate(st).endswith("(stale)")
    st = ws.snapshot(t + 10.0)
    assert st.rate_hz is None and st.bandwidth_bps is None and st.count == 0 and st.total == 20
    assert fmt_rate(st) == "— (stale)"


def test_one_message_has_no_rate_but_a_bandwidth() -> None:
    ws = WindowStats()
    ws.add(1.0, 50)
    st = ws.snapshot(2.0)
    assert st.rate_hz is None and st.bandwidth_bps == pytest.approx(50.0)
    assert fmt_rate(st) == "—"
    assert WindowStats().snapshot(0.0) == Stats()


def test_bad_window_is_rejected() -> None:
    with pytest.raises(ValueError, match="window"):
        WindowStats(window_s=0.0)
    with pytest.raises(ValueError, match="window"):
        WindowStats(window_s=float("nan"))
    with pytest.raises(ValueError, match="samples"):
        WindowStats(max_samples=1)


def test_reset() -> None:
    ws = WindowStats()
    feed(ws, 10.0, 5, 1)
    ws.reset()
    assert ws.snapshot(1.0) == Stats()


def test_formatting() -> None:
    assert fmt_bandwidth(None) == "—"
    assert fmt_bandwidth(512.4) == "512 B/s"
    assert fmt_bandwidth(12_345.0) == "12.3 KB/s"
    assert fmt_bandwidth(4_560_000.0) == "4.56 MB/s"
    assert fmt_rate(Stats(rate_hz=9.996, total=5)) == "10 Hz"


def test_topic_list_merges_the_master_list() -> None:
    tl = TopicList()
    assert tl.update([("/b", "std_msgs/String"), ("/a", "sensor_msgs/Image"), ("/c", "sensor_msgs/Image")]) == []
    assert tl.names() == ["/a", "/b", "/c"]
    assert tl.of_type("sensor_msgs/Image") == ["/a", "/c"]
    tl.set_ticked("/b", True)
    tl.update([("/a", "sensor_msgs/Image")])  # /b and /c disappear
    assert tl.names() == ["/a", "/b"]  # the ticked one stays, marked
    assert not tl.rows["/b"].published and tl.rows["/b"].ticked
    assert tl.update([("/a", "sensor_msgs/Image"), ("/b", "std_msgs/Int32")]) == ["/b"]  # back, new type
    assert tl.rows["/b"].published and tl.rows["/b"].type == "std_msgs/Int32"
    tl.update([("/a", "sensor_msgs/Image")])
    tl.set_ticked("/b", False)  # unticking a vanished topic drops it
    assert tl.names() == ["/a"]
