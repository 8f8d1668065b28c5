"""ROS glue shared by the navigation nodes (imports rospy/tf2): timers that survive time jumping
back, planar tf lookups."""
from __future__ import annotations

import threading
from collections.abc import Callable

import rospy
import tf2_ros

from chefbot_common.geometry import Pose2D
from chefbot_navigation.ros_io import transform_to_pose2d

TF_ERRORS = (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException)


def periodic(rate_hz: float, fn: Callable[[], None]) -> threading.Thread:
    """Call ``fn`` at ``rate_hz`` (ROS time) in a daemon thread that survives time jumping back
    (a rospy.Timer thread dies with ROSTimeMovedBackwardsException)."""

    def loop() -> None:
        rate = rospy.Rate(rate_hz)
        while not rospy.is_shutdown():
            try:
                rate.sleep()
            except rospy.ROSTimeMovedBackwardsException:
                rate = rospy.Rate(rate_hz)
                continue
            except rospy.ROSInterruptException:
                return
            fn()

    thread = threading.Thread(target=loop, daemon=True)
    thread.start()
    return thread


def revive_action_status_timer(server, who: str) -> None:
    """actionlib's ActionServer publishes ``status`` from a rospy.Timer, whose thread dies when
    time jumps back (ROSTimeMovedBackwardsException); start a new one so clients keep
    receiving status.  ``server`` is a SimpleActionServer."""
    srv = getattr(server, "action_server", None)
    timer = getattr(srv, "status_timer", None)
    if timer is not None and not timer.is_alive() and not rospy.is_shutdown():
        rospy.logwarn("%s: restarting actionlib's status timer after a time jump", who)
        srv.status_timer = rospy.Timer(timer._period, srv.publish_status_async)


def lookup_pose2d(buffer: tf2_ros.Buffer, target: str, source: str, stamp: rospy.Time | None = None,
                  timeout: float = 0.0) -> tuple[Pose2D | None, float, str]:
    """Planar pose of ``source`` in ``target`` (latest when ``stamp`` is None), its stamp (s), and ''
    -- or (None, nan, why) when tf has no such transform."""
    try:
        t = buffer.lookup_transform(target, source, stamp or rospy.Time(0), rospy.Duration(timeout))
    except TF_ERRORS as exc:
        return None, float("nan"), f"no transform {target} -> {source}: {exc}"
    return transform_to_pose2d(t), t.header.stamp.to_sec(), ""
