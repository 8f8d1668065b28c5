"""ROS side of the GUI: the ``move_base`` action client and the subscriptions.

Every ROS callback runs in a rospy thread and only *emits a Qt signal*; the
window's slots (GUI thread) feed the presenter.  Nothing here blocks the GUI
thread: the server check (wall clock, never blocking) and the tf look-ups run in a
watcher thread; ``send_goal``/``cancel_goal`` only publish.

No widget code here: the bridge is a ``QObject`` so it can own signals.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from functools import partial

import rospy
import tf2_ros
from actionlib_msgs.msg import GoalStatus, GoalStatusArray
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseWithCovarianceStamped
from move_base_msgs.msg import MoveBaseAction, MoveBaseFeedback, MoveBaseGoal
from nav_msgs.msg import OccupancyGrid, Path
from PyQt5.QtCore import QObject, pyqtSignal
from sensor_msgs.msg import BatteryState

from chefbot_common.geometry import quaternion_from_yaw, yaw_from_quaternion
from chefbot_common.grid import GridInfo
from chefbot_gui import geometry
from chefbot_gui.presenter import Destination, Outcome
from chefbot_navigation.ros_util import GoalClient

_OUTCOMES = {
    GoalStatus.SUCCEEDED: Outcome.SUCCEEDED,
    GoalStatus.ABORTED: Outcome.ABORTED,
    GoalStatus.REJECTED: Outcome.REJECTED,
    GoalStatus.PREEMPTED: Outcome.PREEMPTED,
    GoalStatus.RECALLED: Outcome.PREEMPTED,
    GoalStatus.LOST: Outcome.LOST,
}


@dataclass(frozen=True)
class BridgeParams:
    """Names and timings of the bridge (see the package README for the ROS params).

    ``server_poll_s``: how often the watcher looks for the server while it is missing (s);
    ``status_timeout_s``: action status older than this means the server is gone (s)
    (action servers publish status at 5 Hz); ``pose_period_s``: tf poll period (s).
    """

    action: str = "move_base"
    map_frame: str = "map"
    base_frame: str = "base_footprint"
    map_topic: str = "map"
    plan_topic: str = "move_base/global_plan"
    amcl_topic: str = "amcl_pose"
    battery_topic: str = "battery_state"
    diagnostics_topic: str = "diagnostics"
    server_poll_s: float = 0.5
    status_timeout_s: float = 2.0
    pose_period_s: float = 0.2


def goal_message(dest: Destination, frame: str, stamp: rospy.Time) -> MoveBaseGoal:
    """A ``MoveBaseGoal`` at ``dest.pose`` in ``frame`` with a unit quaternion."""
    goal = MoveBaseGoal()
    goal.target_pose.header.frame_id = frame
    goal.target_pose.header.stamp = stamp
    goal.target_pose.pose.position.x = float(dest.pose.x)
    goal.target_pose.pose.position.y = float(dest.pose.y)
    q = goal.target_pose.pose.orientation
    q.x, q.y, q.z, q.w = quaternion_from_yaw(float(dest.pose.yaw))
    return goal


def grid_from_message(msg: OccupancyGrid) -> tuple[bytes, GridInfo]:
    """Grey image bytes and placement of an ``OccupancyGrid`` (done off the GUI thread)."""
    info = msg.info
    o = info.origin
    q = o.orientation
    yaw = yaw_from_quaternion(q.x, q.y, q.z, q.w, zero_policy="identity")
    grid = GridInfo(info.resolution, info.width, info.height, o.position.x, o.position.y, yaw)
    return geometry.grid_to_grey(msg.data, info.width, info.height), grid


class RosBridge(QObject):
    """``move_base`` client + topic subscriptions, reporting through Qt signals.

    Implements the presenter's ``RobotPort`` (``send_goal``, ``cancel_goal``).
    Call :meth:`start` after connecting the signals and :meth:`shutdown` at exit.
    """

    serverConnected = pyqtSignal(bool)
    goalDone = pyqtSignal(int, str, str)          # goal id, Outcome value, server status text
    robotPose = pyqtSignal(float, float, float)   # x m, y m, yaw rad in the map frame
    planReceived = pyqtSignal(object)             # list[(x, y)] in the map frame
    mapReceived = pyqtSignal(object, object)      # grey bytes, GridInfo
    batteryReceived = pyqtSignal(float, float, bool)  # percentage 0..1 (NaN unknown), V, present
    diagnosticReceived = pyqtSignal(str, int, str)    # name, level, message

    def __init__(self, params: BridgeParams | None = None, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.p = params or BridgeParams()
        self._client = GoalClient(self.p.action, MoveBaseAction)   # SimpleActionClient minus its race
        self._tf = tf2_ros.Buffer(cache_time=rospy.Duration(10.0))
        self._tf_listener: tf2_ros.TransformListener | None = None
        self._subs: list[rospy.Subscriber] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_status = -math.inf   # monotonic time of the last action status message
        self._last_tf_pose = -math.inf  # monotonic time tf last gave the robot pose
        self._lock = threading.Lock()   # guards the goal id against callbacks of replaced goals
        self._goal_id = 0
        self._reported = False  # goalDone already emitted for _goal_id
        self._closed = False  # after shutdown(): queued GUI events may still ask to cancel

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Subscribe and start the watcher thread (server connection + tf pose)."""
        p = self.p
        self._tf_listener = tf2_ros.TransformListener(self._tf)
        sub = rospy.Subscriber
        self._subs = [
            sub(p.action.rstrip("/") + "/status", GoalStatusArray, self._on_status, queue_size=1),
            sub(p.map_topic, OccupancyGrid, self._on_map, queue_size=1),
            sub(p.plan_topic, Path, self._on_plan, queue_size=1),
            sub(p.amcl_topic, PoseWithCovarianceStamped, self._on_amcl, queue_size=1),
            sub(p.battery_topic, BatteryState, self._on_battery, queue_size=1),
            sub(p.diagnostics_topic, DiagnosticArray, self._on_diagnostics, queue_size=5),
        ]
        self._thread = threading.Thread(target=self._watch, name="chefbot_gui_watcher", daemon=True)
        self._thread.start()

    def shutdown(self) -> None:
        """Stop the watcher and drop every subscription; the goal at the server is left alone."""
        self._stop.set()
        self._closed = True
        if self._thread is not None:
            self._thread.join(timeout=self.p.server_poll_s + 2.0)
            self._thread = None
        for s in self._subs:
            s.unregister()
        self._subs = []
        if self._tf_listener is not None:
            self._tf_listener.unregister()
            self._tf_listener = None
        self._client.action_client.stop()

    # ------------------------------------------------------------------ RobotPort
    def send_goal(self, goal_id: int, dest: Destination) -> None:
        """Send ``dest`` to move_base; results are reported as ``goalDone(goal_id, …)``."""
        with self._lock:
            self._goal_id = goal_id
            self._reported = False
        if self._closed:
            return
        goal = goal_message(dest, self.p.map_frame, rospy.Time.now())
        rospy.loginfo("chefbot_gui: goal %d: %s at (%.4g, %.4g, %.3g rad)", goal_id, dest.key,
                      dest.pose.x, dest.pose.y, dest.pose.yaw)
        try:
            self._client.send_goal(goal, done_cb=partial(self._on_done, goal_id),
                                   feedback_cb=partial(self._on_feedback, goal_id))
        except rospy.ROSException as e:  # node shutting down: report like a vanished server
            rospy.logwarn(f"chefbot_gui: goal {goal_id} not sent: {e}")
            self._report(goal_id, GoalStatus.LOST, str(e))
            return

    def cancel_goal(self) -> None:
        """Cancel the goal this GUI sent (other clients' goals are left alone)."""
        if self._closed:
            return
        rospy.loginfo("chefbot_gui: cancel")
        try:
            self._client.cancel_goal()
        except rospy.ROSException as e:  # node shutting down; nothing left to cancel with
            rospy.logwarn(f"chefbot_gui: cancel not sent: {e}")

    # ------------------------------------------------------------------ watcher thread
    def _watch(self) -> None:
        connected: bool | None = None
        next_pose = 0.0
        while not self._stop.is_set() and not rospy.is_shutdown():
            ok = self._server_alive()
            if ok != connected:
                connected = ok
                rospy.loginfo("chefbot_gui: navigation server %s", "connected" if ok else "not connected")
                self.serverConnected.emit(ok)
            now = time.monotonic()
            if now >= next_pose:
                next_pose = now + self.p.pose_period_s
                self._poll_tf()
            self._stop.wait(self.p.pose_period_s if ok else min(self.p.server_poll_s, self.p.pose_period_s))

    def _server_alive(self) -> bool:
        """Is the action server there? Wall-clock and never blocking.

        Not actionlib's ``wait_for_server``: its timeout counts ROS time, which stands
        still with the simulation's /clock, so if the whole simulation died this thread
        would wait forever and the window would keep saying "connected". Instead: the
        server's status stream (5 Hz) is fresh, and it is subscribed to our goals (a
        killed server's connections can linger a moment; its status stops at once).
        """
        fresh = time.monotonic() - self._last_status < self.p.status_timeout_s
        return fresh and self._client.action_client.pub_goal.get_num_connections() > 0

    def _poll_tf(self) -> None:
        try:
            t = self._tf.lookup_transform(self.p.map_frame, self.p.base_frame, rospy.Time(0))
        except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException):
            return
        tr, q = t.transform.translation, t.transform.rotation
        self._last_tf_pose = time.monotonic()
        self.robotPose.emit(tr.x, tr.y, yaw_from_quaternion(q.x, q.y, q.z, q.w, zero_policy="identity"))

    def _tf_fresh(self) -> bool:
        return time.monotonic() - self._last_tf_pose < 1.0

    # ------------------------------------------------------------------ rospy callbacks
    def _on_status(self, _msg: GoalStatusArray) -> None:
        self._last_status = time.monotonic()

    def _on_done(self, goal_id: int, state: int, _result) -> None:
        self._report(goal_id, state, self._client.get_goal_status_text())

    def _report(self, goal_id: int, state: int, text: str | None) -> None:
        """Emit ``goalDone`` once per goal, and only for the latest goal."""
        with self._lock:
            if goal_id != self._goal_id or self._reported:
                return
            self._reported = True
        text = text or ""
        outcome = _OUTCOMES.get(state, Outcome.ABORTED)
        rospy.loginfo("chefbot_gui: goal %d ended %s %s", goal_id, outcome.value, text)
        self.goalDone.emit(goal_id, outcome.value, text)

    def _on_feedback(self, _goal_id: int, fb: MoveBaseFeedback) -> None:
        # move_base feedback is the robot pose; tf is preferred while it is available
        if self._tf_fresh():
            return
        pose = fb.base_position
        if pose.header.frame_id and pose.header.frame_id.lstrip("/") != self.p.map_frame:
            return
        o = pose.pose.orientation
        self.robotPose.emit(pose.pose.position.x, pose.pose.position.y,
                            yaw_from_quaternion(o.x, o.y, o.z, o.w, zero_policy="identity"))

    def _on_amcl(self, msg: PoseWithCovarianceStamped) -> None:
        if self._tf_fresh():
            return
        p, o = msg.pose.pose.position, msg.pose.pose.orientation
        self.robotPose.emit(p.x, p.y, yaw_from_quaternion(o.x, o.y, o.z, o.w, zero_policy="identity"))

    def _on_plan(self, msg: Path) -> None:
        frame = msg.header.frame_id.lstrip("/")
        if frame and frame != self.p.map_frame:
            rospy.logwarn_throttle(10.0, f"chefbot_gui: plan in frame {frame!r}, expected {self.p.map_frame!r}")
            return
        self.planReceived.emit([(ps.pose.position.x, ps.pose.position.y) for ps in msg.poses])

    def _on_map(self, msg: OccupancyGrid) -> None:
        try:
            grey, grid = grid_from_message(msg)
        except ValueError as e:
            rospy.logwarn(f"chefbot_gui: map ignored: {e}")
            return
        self.mapReceived.emit(grey, grid)

    def _on_battery(self, msg: BatteryState) -> None:
        self.batteryReceived.emit(float(msg.percentage), float(msg.voltage), bool(msg.present))

    def _on_diagnostics(self, msg: DiagnosticArray) -> None:
        for st in msg.status:
            self.diagnosticReceived.emit(st.name, int(st.level), st.message)
