"""move_base's other-robots source (ROS glue: rospy): ``/fleet/robots`` into the robots layer.

Reads ``~robots_layer/<name>`` (:class:`chefbot_navigation.robots_layer.RobotsLayerParams`), subscribes
``chefbot_msgs/RobotState`` on its topic when ``enabled`` (every robot of the site publishes its own
there, latched), keeps the newest state per robot and redraws the
:class:`~chefbot_navigation.robots_layer.RobotsLayer` of the current costmap five times a second (a
new map gets a new layer, filled with the states known so far).  States in another frame than the
global frame, or unusable ones, are logged (throttled) and skipped.
"""
from __future__ import annotations

import threading
from collections.abc import Callable

import numpy as np
import rospy

from chefbot_common.params import private_spec
from chefbot_msgs.msg import RobotState
from chefbot_navigation.costmap import LayeredCostmap
from chefbot_navigation.health import TaskHealth
from chefbot_navigation.robots_layer import OtherRobot, RobotsLayer, RobotsLayerParams
from chefbot_navigation.ros_util import periodic

ROBOTS = private_spec(RobotsLayerParams, "robots_layer/")   # move_base's ~robots_layer/<name> params
REFRESH_HZ = 5.0


def state_to_robot(msg: RobotState) -> OtherRobot:
    """A RobotState message as the layer's :class:`OtherRobot` (no checks: :meth:`OtherRobot.check`)."""
    return OtherRobot(
        name=msg.name, stamp=msg.header.stamp.to_sec(), x=msg.pose.x, y=msg.pose.y, yaw=msg.pose.theta,
        v=msg.velocity.linear.x, w=msg.velocity.angular.z,
        footprint=np.array([[p.x, p.y] for p in msg.footprint], dtype=float).reshape(-1, 2),
        radius=float(msg.footprint_radius),
        path=np.array([[p.x, p.y] for p in msg.path], dtype=float).reshape(-1, 2))


class RobotsInput:
    """The subscription, the states and the periodic redraw; ``layers()`` returns move_base's current
    costmap layers."""

    def __init__(self, global_frame: str, lock: threading.RLock,
                 layers: Callable[[], LayeredCostmap | None]) -> None:
        self.params = ROBOTS.read(rospy.get_param)
        self.own_name = self.params.own_name or rospy.get_namespace().strip("/")
        self.global_frame, self.lock, self.layers = global_frame.lstrip("/"), lock, layers
        self.states: dict[str, OtherRobot] = {}
        self.task: threading.Thread | None = None
        if self.params.enabled:
            rospy.Subscriber(self.params.topic, RobotState, self.on_state, queue_size=20)
            self.task = periodic(REFRESH_HZ, self.refresh, TaskHealth("move_base: robots layer"))
            rospy.loginfo("move_base: other robots from %s (this robot: %r), dropped after %.3g s",
                          rospy.resolve_name(self.params.topic), self.own_name, self.params.timeout)

    def on_state(self, msg: RobotState) -> None:
        """Keep a state (not this robot's own) and hand it to the current layer."""
        if msg.name == self.own_name:
            return
        if msg.header.frame_id.lstrip("/") != self.global_frame:
            rospy.logwarn_throttle(10.0, f"move_base: state of robot {msg.name!r} ignored: frame "
                                         f"{msg.header.frame_id!r}, not {self.global_frame!r}")
            return
        robot = state_to_robot(msg)
        try:
            robot.check()
        except ValueError as exc:
            rospy.logwarn_throttle(10.0, f"move_base: robot state ignored: {exc}")
            return
        with self.lock:
            old = self.states.get(robot.name)
            if old is None or robot.stamp >= old.stamp:
                self.states[robot.name] = robot
            if old is None:
                rospy.loginfo("move_base: robot %r on %s", robot.name, rospy.resolve_name(self.params.topic))

    def refresh(self) -> None:
        """Drop stale states, redraw the layer of the current costmap (when anything is or was drawn)."""
        now = rospy.get_time()
        with self.lock:
            for name in [n for n, r in self.states.items() if now - r.stamp > self.params.timeout]:
                del self.states[name]
                rospy.loginfo("move_base: robot %r dropped: no state for %.3g s", name, self.params.timeout)
            layers = self.layers()
            if layers is None:
                return
            lay = layers.robots_layer
            if lay is None:
                if not self.states:
                    return
                lay = layers.robots_layer = RobotsLayer(layers.info, self.params, self.own_name)
            if not self.states and not lay.robots:
                return
            for name in set(lay.robots) - set(self.states):
                lay.forget(name)
            for robot in self.states.values():
                lay.update(robot)
            lay.refresh(now)
            layers.layers_changed()

    def summary(self) -> str:
        """The robots the layer knows, for /diagnostics."""
        with self.lock:
            names = sorted(self.states)
        return f"{len(names)} other robot(s)" + (f": {', '.join(names)}" if names else "")
