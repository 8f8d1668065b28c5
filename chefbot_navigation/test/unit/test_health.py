"""Periodic tasks survive exceptions (counted, throttled logs, diagnostics level); scans never wait on
the planner's lock (PendingQueue)."""
from __future__ import annotations

import threading

import pytest

from chefbot_navigation.health import ERROR, OK, WARN, PendingQueue, TaskHealth


def test_task_health_counts_and_throttles_logs() -> None:
    h = TaskHealth("costmap publisher", log_period=10.0, recent_window=30.0)
    h.ok()
    assert h.status(0.0)[0] == OK
    first = h.failed(MemoryError("Unable to allocate 2.98 GiB"), 1.0)
    assert first is not None and "MemoryError: Unable to allocate 2.98 GiB" in first and "keeps running" in first
    assert h.failed(MemoryError("again"), 2.0) is None          # throttled
    assert h.failed(MemoryError("again"), 5.0) is None
    later = h.failed(ValueError("bad"), 11.5)
    assert later is not None and "3 failures since the last report, 4 in all" in later
    level, text, values = h.status(12.0)
    assert level == ERROR and "4 of 5 calls failed" in text and values["errors"] == 4
    assert h.status(100.0)[0] == WARN    # old failures only warn


def test_task_health_logs_again_after_time_jumped_back() -> None:
    h = TaskHealth("t", log_period=10.0)
    assert h.failed(RuntimeError("x"), 50.0) is not None
    assert h.failed(RuntimeError("x"), 3.0) is not None   # clock restarted: not throttled for ever


def test_pending_queue_put_never_waits_for_the_consumer_lock() -> None:
    planner_lock = threading.Lock()
    q = PendingQueue(maxlen=3)
    with planner_lock:                      # a long plan holds the node's lock ...
        done = threading.Event()

        def scan_callback() -> None:
            for i in range(5):
                q.put(i)
            done.set()

        t = threading.Thread(target=scan_callback)
        t.start()
        # ... and the scan callback still finishes (it would deadlock here if it needed planner_lock)
        assert done.wait(30.0), "scan callback waited for the planner's lock"
        t.join()
    assert q.drain() == [2, 3, 4] and q.dropped == 2 and len(q) == 0
    with pytest.raises(ValueError, match="maxlen"):
        PendingQueue(0)


def test_periodic_keeps_running_after_exceptions() -> None:
    rospy = pytest.importorskip("rospy")
    from chefbot_navigation import ros_util

    rospy.rostime.set_rostime_initialized(True)     # wall clock, no master needed
    calls: list[int] = []
    enough = threading.Event()

    def flaky() -> None:
        calls.append(1)
        if len(calls) >= 4:
            enough.set()
        if len(calls) % 2:
            raise MemoryError("Unable to allocate 2.98 GiB")

    logged: list[str] = []
    orig = rospy.logerr
    rospy.logerr = lambda msg, *a: logged.append(msg % a if a else msg)
    try:
        thread = ros_util.periodic(50.0, flaky, TaskHealth("flaky", log_period=3600.0))
        assert enough.wait(60.0), "periodic thread died after the first exception"
    finally:
        rospy.logerr = orig
    assert thread.is_alive()
    assert thread.health.errors >= 2 and thread.health.calls >= 4
    assert len(logged) == 1 and "MemoryError" in logged[0]     # throttled: one line for many failures


def test_stale_reason_names_the_silent_odometry() -> None:
    """move_base's stale-pose reason names the stale tf link and its publisher (tf2's frames yaml),
    with the odometry hint when the stale link is the one ending in the robot base."""
    import rospy
    import tf2_py
    import yaml
    from geometry_msgs.msg import TransformStamped

    from chefbot_navigation.navigator import link_fault, stalest_link

    def frames(map_odom: float, odom_base: float) -> dict:
        buf = tf2_py.BufferCore()
        for parent, child, stamp, who in (("map", "odom", map_odom, "/amcl"),
                                          ("odom", "base_footprint", odom_base, "/diff_tf")):
            t = TransformStamped()
            t.header.frame_id, t.child_frame_id, t.header.stamp = parent, child, rospy.Time.from_sec(stamp)
            t.transform.rotation.w = 1.0
            buf.set_transform(t, who)
        return yaml.safe_load(buf.all_frames_as_yaml())

    link = stalest_link(frames(10.0, 4.0), "base_footprint", "map", 12.0)
    assert link_fault(link, 0.5, "base_footprint") == (
        "stale link odom -> base_footprint (from /diff_tf), not updated for 8.00 s "
        "(no odometry: drive, board link or encoders down?)")
    # amcl's link is the stale one: named, without the odometry hint
    link = stalest_link(frames(4.0, 10.0), "base_footprint", "map", 12.0)
    assert link_fault(link, 0.5, "base_footprint") == "stale link map -> odom (from /amcl), not updated for 8.00 s"
