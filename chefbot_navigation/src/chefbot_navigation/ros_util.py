"""ROS glue shared by the navigation nodes (imports rospy/tf2): timers that survive time jumping
back, planar tf lookups (:class:`PlanarTf`)."""
from __future__ import annotations

import threading
from collections.abc import Callable

import rospy
import tf2_ros

from chefbot_common.geometry import Pose2D
from chefbot_navigation.navigator import pose_age_fault
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


class PlanarTf:
    """A tf2 buffer and listener answering planar questions about frames in one global frame."""

    def __init__(self, global_frame: str, cache_time: float = 10.0) -> None:
        self.global_frame = global_frame
        self.buffer = tf2_ros.Buffer(cache_time=rospy.Duration(cache_time))
        self.listener = tf2_ros.TransformListener(self.buffer)

    def lookup(self, source: str, stamp: rospy.Time | None = None,
               timeout: float = 0.0) -> tuple[Pose2D | None, float, str]:
        """Planar pose of ``source`` in the global frame (latest when ``stamp`` is None), its stamp (s),
        and '' -- or (None, nan, why) when tf has no such transform."""
        try:
            t = self.buffer.lookup_transform(self.global_frame, source, stamp or rospy.Time(0),
                                             rospy.Duration(timeout))
        except TF_ERRORS as exc:
            return None, float("nan"), f"no transform {self.global_frame} -> {source}: {exc}"
        return transform_to_pose2d(t), t.header.stamp.to_sec(), ""

    def fresh_pose(self, child: str, tolerance: float) -> tuple[Pose2D | None, str]:
        """Latest pose of ``child`` if at most ``tolerance`` s old, else None and why."""
        pose, stamp, why = self.lookup(child)
        why = why or pose_age_fault(rospy.get_time() - stamp, tolerance, self.global_frame, child)
        return (None, why) if why else (pose, "")

    def clear(self) -> None:
        """Forget every transform (time jumped back)."""
        self.buffer.clear()
