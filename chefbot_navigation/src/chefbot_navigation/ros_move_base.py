"""ROS side of the move_base node (imports rospy/actionlib): footprint loading, the costmap
publishers, the ``make_plan`` / ``clear_costmaps`` services, actionlib's cancel workaround,
goals into the global frame and the goal's outputs (plans, current goal, navigation state).

Kept out of ``nodes/move_base`` so that the node stays wiring; every navigation decision is
still ``Navigator.step``'s.  ``node`` below is the node's ``MoveBase`` object (its lock,
layers, navigator, ``robot_pose``, ``goal_to_map``, ``apply_scans``, params).
"""
from __future__ import annotations

import threading
from collections.abc import Callable
from dataclasses import dataclass, field
from functools import partial
from typing import Any

import numpy as np
import rospy
from geometry_msgs.msg import Point32, PolygonStamped, Pose, PoseStamped, Quaternion
from nav_msgs.msg import OccupancyGrid, Path
from nav_msgs.srv import GetPlan, GetPlanResponse
from std_msgs.msg import String
from std_srvs.srv import Empty, EmptyResponse

from chefbot_common.geometry import Pose2D
from chefbot_common.params import ParamError, ParamSpec
from chefbot_navigation.controller import arc_points
from chefbot_navigation.footprint import Footprint, resolve_footprint
from chefbot_navigation.health import TaskHealth
from chefbot_navigation.navigator import Goal, GoalError, parse_goal
from chefbot_navigation.planners import PlanningError
from chefbot_navigation.ros_io import occupancy_to_msg, path_to_msg, pose2d_to_pose
from chefbot_navigation.ros_util import PlanarTf, periodic


@dataclass(frozen=True)
class UrdfParams:
    """The robot model, for the footprint."""

    robot_description: str = field(default="", repr=False)   # URDF (relative name, as robot_state_publisher's):
                                                              #   the footprint when costmap/footprint is urdf


URDF = ParamSpec(UrdfParams, {"robot_description": "robot_description"})


def load_footprint(cost_p: Any, base_frame: str = "base_footprint") -> Footprint:
    """The robot's footprint from the costmap params (or the URDF on ``robot_description`` (:data:`URDF`),
    in ``base_frame``: the robot_base_frame, prefixed in a namespace), logged; ParamError naming the
    problem if it is unusable."""
    try:
        urdf = URDF.read(rospy.get_param).robot_description
        footprint, source = resolve_footprint(cost_p.footprint, cost_p.footprint_padding, cost_p.robot_radius,
                                              urdf, base_frame)
    except ValueError as exc:
        raise ParamError(f"footprint: {exc}") from None
    rospy.loginfo("move_base: footprint from %s: inscribed radius %.3f m, circumscribed %.3f m",
                  source, footprint.inscribed_radius, footprint.circumscribed_radius)
    return footprint


class CostmapPublishers:
    """``~global_costmap/costmap`` (latched, whole map) and ``~local_costmap/costmap`` (a window of
    ``nav_p.local_window`` m around the robot), each at its publish frequency (Hz; 0 = never);
    with the local window, ``~local_costmap/footprint`` (the padded footprint at the robot's pose,
    in the global frame, as costmap_2d's ``footprint`` topic: RViz's Polygon display)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        self.pub_global = rospy.Publisher("~global_costmap/costmap", OccupancyGrid, queue_size=1, latch=True)
        self.pub_local = rospy.Publisher("~local_costmap/costmap", OccupancyGrid, queue_size=1)
        self.pub_footprint = rospy.Publisher("~local_costmap/footprint", PolygonStamped, queue_size=1)

    def start(self) -> list[threading.Thread]:
        """Start the publishing threads (:func:`periodic`); returns them for the diagnostics."""
        np_, tasks = self.node.np, []
        if np_.global_publish_frequency > 0:
            tasks.append(periodic(np_.global_publish_frequency, self.publish,
                                  TaskHealth("move_base: global costmap publisher")))
        if np_.local_publish_frequency > 0:
            tasks.append(periodic(np_.local_publish_frequency, lambda: self.publish(local_only=True),
                                  TaskHealth("move_base: local costmap publisher")))
        return tasks

    def publish(self, local_only: bool = False) -> None:
        """Publish the global costmap, or the local window (skipped while the robot pose is unknown)."""
        node = self.node
        pose = node.robot_pose()[0] if local_only else None
        with node.lock:
            if node.layers is None or (local_only and pose is None):
                return
            w = node.nav_p.local_window
            node.apply_scans()
            cm = node.layers.window(pose.x, pose.y, w, w) if local_only else node.layers.master()
        pub = self.pub_local if local_only else self.pub_global
        stamp = rospy.Time.now()
        pub.publish(occupancy_to_msg(cm.to_occupancy(), stamp, node.np.global_frame))
        if local_only:
            self.pub_footprint.publish(footprint_to_msg(node.footprint, pose, stamp, node.np.global_frame))


def footprint_to_msg(footprint: Footprint, pose: Pose2D, stamp: rospy.Time, frame: str) -> PolygonStamped:
    """The footprint polygon (robot frame, m) placed at ``pose`` (``frame``, m / rad)."""
    c, s = np.cos(pose.yaw), np.sin(pose.yaw)
    pts = footprint.polygon @ np.array([[c, s], [-s, c]]) + (pose.x, pose.y)
    msg = PolygonStamped()
    msg.header.stamp, msg.header.frame_id = stamp, frame
    msg.polygon.points = [Point32(float(x), float(y), 0.0) for x, y in pts]
    return msg


class PlanServices:
    """Services ``~make_plan`` and ``make_plan`` (nav_msgs/GetPlan) and ``~clear_costmaps`` (std_srvs/Empty)."""

    def __init__(self, node: Any) -> None:
        self.node = node
        rospy.Service("~make_plan", GetPlan, self.make_plan)
        rospy.Service("make_plan", GetPlan, self.make_plan)
        rospy.Service("~clear_costmaps", Empty, self.clear)

    def clear(self, _req) -> EmptyResponse:
        """~clear_costmaps: forget the scan obstacles."""
        with self.node.lock:
            if self.node.layers is not None:
                self.node.layers.clear_obstacles()
        rospy.loginfo("move_base: costmaps cleared")
        return EmptyResponse()

    def make_plan(self, req) -> GetPlanResponse:
        """make_plan: a plan from ``req.start`` (or the robot) to ``req.goal``; an empty plan (warned) if none."""
        node, frame = self.node, self.node.np.global_frame
        resp = GetPlanResponse()
        resp.plan.header = rospy.Header(stamp=rospy.Time.now(), frame_id=frame)
        try:
            goal = node.goal_to_map(req.goal)
            if req.start.header.frame_id:
                # only the start position matters: an all-zero start quaternion must not fail
                start_ps = PoseStamped(header=req.start.header, pose=Pose(req.start.pose.position, Quaternion(w=1)))
                start = node.goal_to_map(start_ps)
            else:
                start, why = node.robot_pose()
                if start is None:
                    raise GoalError(why)
            with node.lock:
                if node.navigator is None:
                    raise GoalError(node.map_fault)
                node.apply_scans()
                plan = node.navigator.plan_between((start.x, start.y), goal)
        except (GoalError, PlanningError) as exc:
            rospy.logwarn("move_base: make_plan failed: %s", exc)
            return resp
        resp.plan = path_to_msg(plan.points, None, rospy.Time.now(), frame)
        if goal.yaw is not None and resp.plan.poses:
            # like ROS: the last pose carries the goal's orientation
            resp.plan.poses[-1].pose = pose2d_to_pose(Pose2D(goal.x, goal.y, goal.yaw))
        return resp


def guard_goalless_cancel(server) -> None:
    """Install :func:`cancel_skipping_goalless` on a SimpleActionServer (call before its start())."""
    asv = server.action_server
    asv.internal_cancel_callback = partial(cancel_skipping_goalless, asv, asv.internal_cancel_callback)


def cancel_skipping_goalless(asv, actionlib_cancel: Callable[[Any], None], goal_id) -> None:
    """A cancel that overtakes its goal (separate topics) leaves actionlib a tracker without a goal;
    any later cancel-all then logs "Attempt to get a goal id on an uninitialized ServerGoalHandle"
    for it. Such a tracker is already RECALLING/RECALLED: keep it out of the cancel."""
    with asv.lock:
        if any(st.goal is None and st.status.goal_id.id == goal_id.id for st in asv.status_list):
            return
        goalless = [st for st in asv.status_list if st.goal is None]
        asv.status_list = [st for st in asv.status_list if st.goal is not None]
        try:
            actionlib_cancel(goal_id)
        finally:
            asv.status_list.extend(goalless)


def goal_to_map(tf: PlanarTf, ps: PoseStamped, zero_quaternion_policy: str) -> Goal:
    """Goal in ``tf``'s global frame: quaternion checked/normalised, other frames through tf2;
    GoalError saying why if unusable."""
    p, q = ps.pose.position, ps.pose.orientation
    local, has_yaw = parse_goal((p.x, p.y, p.z), (q.x, q.y, q.z, q.w), zero_quaternion_policy)
    frame = ps.header.frame_id.lstrip("/") or tf.global_frame
    if frame != tf.global_frame:
        pose, _, why = tf.lookup(frame, timeout=0.5)
        if pose is None:
            raise GoalError(f"cannot transform goal from frame '{frame}': {why}")
        local = pose.compose(local)
    return Goal(local.x, local.y, local.yaw if has_yaw else None)


class GoalOutputs:
    """What move_base publishes about the goal: ``~global_plan`` and ``~current_goal`` (latched),
    ``~local_plan`` (the commanded arc) and ``~navigation_state`` (the goal's state in words:
    planning, following, blocked ..., recovering: ..., aborted: ...; latched)."""

    def __init__(self, global_frame: str) -> None:
        self.frame = global_frame
        self.pub_plan = rospy.Publisher("~global_plan", Path, queue_size=1, latch=True)
        self.pub_local_plan = rospy.Publisher("~local_plan", Path, queue_size=1)
        self.pub_goal = rospy.Publisher("~current_goal", PoseStamped, queue_size=1, latch=True)
        self.pub_state = rospy.Publisher("~navigation_state", String, queue_size=10, latch=True)
        self.status = "idle"

    def stamped(self, pose: Pose2D) -> PoseStamped:
        """``pose`` stamped now in the global frame."""
        return PoseStamped(header=rospy.Header(stamp=rospy.Time.now(), frame_id=self.frame),
                           pose=pose2d_to_pose(pose))

    def goal(self, goal: Goal) -> None:
        """Publish the accepted goal (yaw 0 when any yaw will do)."""
        self.pub_goal.publish(self.stamped(Pose2D(goal.x, goal.y, goal.yaw or 0.0)))

    def plan(self, points) -> None:
        """Publish a new global plan (N x 2 points, m)."""
        self.pub_plan.publish(path_to_msg(points, None, rospy.Time.now(), self.frame))

    def local_plan(self, pose: Pose2D, v: float, w: float, horizon: float = 1.0) -> None:
        """The arc the current command (m/s, rad/s) drives along over ``horizon`` s (like base_local_planner's)."""
        if self.pub_local_plan.get_num_connections() > 0:
            xs, ys, yaws = arc_points(pose, v, w, np.linspace(0.0, horizon, 11))
            self.pub_local_plan.publish(path_to_msg(np.column_stack((xs, ys)), yaws, rospy.Time.now(), self.frame))

    def report(self, status: str) -> None:
        """A goal status change: logged once at INFO, published on ~navigation_state (and kept for diagnostics)."""
        self.status = status
        rospy.loginfo("move_base: goal status: %s", status)
        self.pub_state.publish(String(status))
