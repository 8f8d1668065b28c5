"""ROS side of the fleet window: the dispatcher's ``deliver`` action, its services, its topics.

Every ROS callback runs in a rospy thread and only *emits a Qt signal*; the fleet window's slots
(GUI thread) feed the presenter.  Nothing here blocks the GUI thread: orders are goals of an
``actionlib.ActionClient`` (one goal per order, several at once; the result arrives in a
callback), each service call runs in a short-lived thread of its own with a time-out, and the
dispatcher check (wall clock) runs in a watcher thread.

Messages are turned into the presenter's plain records by :func:`queue_from_message` and
:func:`report_from_message`, so the window never sees a ROS type.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial

import actionlib
import rospy
from actionlib_msgs.msg import GoalStatus, GoalStatusArray
from nav_msgs.msg import OccupancyGrid
from PyQt5.QtCore import QObject, pyqtSignal

from chefbot_fleet.msg import DeliverAction, DeliverGoal, OrderQueue
from chefbot_fleet.srv import CancelOrder, SetRobot
from chefbot_gui.fleet_presenter import DispatchRobot, OrderInfo, QueueSnapshot, RobotReport
from chefbot_gui.ros_bridge import grid_from_message
from chefbot_msgs.msg import RobotState

SERVICE_CHECK_S = 3.0   # between probes of the dispatcher's services while they answer (s)
_FINAL = {GoalStatus.SUCCEEDED, GoalStatus.ABORTED, GoalStatus.PREEMPTED, GoalStatus.RECALLED,
          GoalStatus.REJECTED, GoalStatus.LOST}


@dataclass(frozen=True)
class FleetBridgeParams:
    """Names and timings of the fleet bridge (see the package README for the ROS params).

    ``fleet_ns``: the dispatcher's namespace (``deliver``, ``cancel_order``, ``set_robot``,
    ``orders`` under it); ``robots_topic``: the robots' ``chefbot_msgs/RobotState``;
    ``map_frame``: frame of the map and of the poses drawn (other frames are ignored);
    ``poll_s``: period of the dispatcher check (s); ``status_timeout_s``: action status older
    than this means the dispatcher is gone (s; action servers publish status at 5 Hz);
    ``service_timeout_s``: how long one service call may wait for its server (s).
    """

    fleet_ns: str = "/fleet"
    robots_topic: str = "/fleet/robots"
    map_topic: str = "map"
    map_frame: str = "map"
    poll_s: float = 0.5
    status_timeout_s: float = 2.0
    service_timeout_s: float = 2.0

    def name(self, leaf: str) -> str:
        """``fleet_ns/leaf``."""
        return f"{self.fleet_ns.rstrip('/')}/{leaf}"


def queue_from_message(msg: OrderQueue) -> QueueSnapshot:
    """The presenter's record of a ``chefbot_fleet/OrderQueue``."""
    orders = tuple(OrderInfo(id=o.id, tables=tuple(o.tables), state=o.state, assigned=o.assigned, reason=o.reason,
                             eta=float(o.eta), priority=float(o.priority), robot=o.robot) for o in msg.orders)
    robots = tuple(DispatchRobot(name=r.name, state=r.state, place=r.place, stops=tuple(r.stops),
                                 orders=tuple(r.orders), reason=r.reason, battery=float(r.battery))
                   for r in msg.robots)
    return QueueSnapshot(orders, robots)


def report_from_message(msg: RobotState) -> RobotReport:
    """The presenter's record of a ``chefbot_msgs/RobotState`` (poses in its header's frame)."""
    return RobotReport(name=msg.name, x=float(msg.pose.x), y=float(msg.pose.y), yaw=float(msg.pose.theta),
                       footprint=tuple((float(p.x), float(p.y)) for p in msg.footprint),
                       radius=float(msg.footprint_radius) if msg.footprint_radius > 0 else 0.178,
                       path=tuple((float(p.x), float(p.y)) for p in msg.path), text=msg.state)


class FleetBridge(QObject):
    """The dispatcher's client, reporting through Qt signals; implements the presenter's ``FleetPort``.

    Call :meth:`start` after connecting the signals and :meth:`shutdown` at exit.
    """

    dispatcherChanged = pyqtSignal(bool, bool)      # deliver action server there, services there
    queueReceived = pyqtSignal(object)              # QueueSnapshot
    robotReceived = pyqtSignal(object)              # RobotReport
    mapReceived = pyqtSignal(object, object)        # grey bytes, GridInfo
    orderAccepted = pyqtSignal(int, str)            # request, status text ("order o7")
    orderRefused = pyqtSignal(int, str)             # request, reason
    orderDone = pyqtSignal(int, str, str, str)      # request, order id, served|cancelled|failed|lost, reason
    replyReceived = pyqtSignal(int, bool, str)      # request, ok, message (service calls)

    def __init__(self, params: FleetBridgeParams | None = None, parent: QObject | None = None) -> None:
        super().__init__(parent)
        self.p = params or FleetBridgeParams()
        self._client = actionlib.ActionClient(self.p.name("deliver"), DeliverAction)
        self._goals: dict[int, actionlib.ClientGoalHandle | None] = {}   # None: being sent
        self._accepted: set[int] = set()
        self._lock = threading.Lock()
        self._subs: list[rospy.Subscriber] = []
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._last_status = -1e18   # monotonic time of the last deliver/status message
        self._closed = False

    # ------------------------------------------------------------------ lifecycle
    def start(self) -> None:
        """Subscribe and start the watcher thread (the dispatcher check)."""
        p = self.p
        self._subs = [
            rospy.Subscriber(p.name("deliver") + "/status", GoalStatusArray, self._on_status, queue_size=1),
            rospy.Subscriber(p.name("orders"), OrderQueue, self._on_queue, queue_size=2),
            rospy.Subscriber(p.robots_topic, RobotState, self._on_robot, queue_size=20),
            rospy.Subscriber(p.map_topic, OccupancyGrid, self._on_map, queue_size=1),
        ]
        self._thread = threading.Thread(target=self._watch, name="chefbot_fleet_gui_watcher", daemon=True)
        self._thread.start()

    def shutdown(self) -> None:
        """Stop the watcher and drop the subscriptions; orders already sent stay with the dispatcher."""
        self._stop.set()
        self._closed = True
        if self._thread is not None:
            self._thread.join(timeout=self.p.poll_s + self.p.service_timeout_s + 2.0)
            self._thread = None
        for s in self._subs:
            s.unregister()
        self._subs = []
        self._client.stop()

    # ------------------------------------------------------------------ FleetPort
    def send_order(self, request: int, tables: Sequence[str], priority: float, robot: str) -> None:
        """One ``deliver`` goal; the dispatcher's answers come back as orderAccepted/Refused/Done."""
        if self._closed:
            return
        goal = DeliverGoal(tables=list(tables), priority=float(priority), robot=robot)
        rospy.loginfo("chefbot_gui: order request %d: %s priority %g robot %r", request, " ".join(tables),
                      priority, robot)
        # in flight before send_goal returns: a quick answer (a refusal) may come back on
        # rospy's thread before the handle does, and must not be taken for one already reported
        with self._lock:
            self._goals[request] = None
        try:
            gh = self._client.send_goal(goal, transition_cb=partial(self._on_transition, request))
        except rospy.ROSException as e:     # node shutting down
            with self._lock:
                self._goals.pop(request, None)
            self.orderDone.emit(request, "", "lost", str(e))
            return
        with self._lock:
            if request in self._goals:      # not answered yet: keep the handle (actionlib holds it weakly)
                self._goals[request] = gh

    def cancel_order(self, request: int, order_id: str) -> None:
        """``cancel_order(order_id)`` in a thread of its own; the answer is replyReceived."""
        self._call(request, "cancel_order", CancelOrder, order_id)

    def set_robot(self, request: int, robot: str, command: str) -> None:
        """``set_robot(robot, command)`` in a thread of its own; the answer is replyReceived."""
        self._call(request, "set_robot", SetRobot, robot, command)

    def _call(self, request: int, leaf: str, kind: type, *args: str) -> None:
        if self._closed:
            return
        threading.Thread(target=self._call_thread, args=(request, self.p.name(leaf), kind, args),
                         name=f"chefbot_fleet_gui_{leaf}", daemon=True).start()

    def _call_thread(self, request: int, service: str, kind: type, args: tuple[str, ...]) -> None:
        try:
            rospy.wait_for_service(service, timeout=self.p.service_timeout_s)
            resp = rospy.ServiceProxy(service, kind)(*args)
        except rospy.ROSException as e:           # not there within the time-out, or shutting down
            self.replyReceived.emit(request, False, f"{service} does not answer ({e})")
            return
        except rospy.ServiceException as e:       # the call failed (the server died mid-call, ...)
            self.replyReceived.emit(request, False, f"{service} failed: {e}")
            return
        rospy.loginfo("chefbot_gui: %s%s: %s %s", service, args, resp.ok, resp.message)
        self.replyReceived.emit(request, bool(resp.ok), resp.message)

    # ------------------------------------------------------------------ action callbacks
    def _on_transition(self, request: int, gh: actionlib.ClientGoalHandle) -> None:
        comm = gh.get_comm_state()
        if comm == actionlib.CommState.ACTIVE or comm == actionlib.CommState.PREEMPTING:
            with self._lock:
                first = request not in self._accepted
                self._accepted.add(request)
            if first:
                self.orderAccepted.emit(request, gh.get_goal_status_text() or "")
        elif comm == actionlib.CommState.DONE:
            with self._lock:
                if request not in self._goals:
                    return       # already reported (as lost)
                del self._goals[request]
            state = gh.get_terminal_state()
            text = gh.get_goal_status_text() or ""
            if state == GoalStatus.REJECTED:
                self.orderRefused.emit(request, text)
                return
            result = gh.get_result()
            if result is None or state not in _FINAL or state == GoalStatus.LOST:
                self.orderDone.emit(request, "", "lost", text)
            else:
                self.orderDone.emit(request, result.order_id, result.state, result.reason)

    # ------------------------------------------------------------------ watcher thread
    def _watch(self) -> None:
        last: tuple[bool, bool] | None = None
        services_ok, next_check = False, 0.0
        while not self._stop.is_set() and not rospy.is_shutdown():
            action_ok = self._action_alive()
            # a service probe opens a connection: every SERVICE_CHECK_S, not every poll
            if not action_ok:
                services_ok = False
            elif time.monotonic() >= next_check or not services_ok:
                services_ok = self._services_alive()
                next_check = time.monotonic() + SERVICE_CHECK_S
            now = (action_ok, services_ok)
            if now != last:
                last = now
                rospy.loginfo("chefbot_gui: dispatcher on %s: action %s, services %s", self.p.fleet_ns,
                              "up" if action_ok else "down", "up" if services_ok else "down")
                self.dispatcherChanged.emit(action_ok, services_ok)
                if not action_ok:
                    self._lose_goals()
            self._stop.wait(self.p.poll_s)

    def _action_alive(self) -> bool:
        """Wall clock, never blocking: fresh status and a subscriber to our goals (see RosBridge)."""
        fresh = time.monotonic() - self._last_status < self.p.status_timeout_s
        return fresh and self._client.pub_goal.get_num_connections() > 0

    def _services_alive(self) -> bool:
        for leaf in ("cancel_order", "set_robot"):
            try:
                rospy.wait_for_service(self.p.name(leaf), timeout=0.2)
            except rospy.ROSException:
                return False
        return True

    def _lose_goals(self) -> None:
        """The dispatcher vanished: its goals will get no answer from this one (its database keeps them)."""
        with self._lock:
            lost, self._goals = list(self._goals), {}
        for request in lost:
            self.orderDone.emit(request, "", "lost", "")

    # ------------------------------------------------------------------ topic callbacks
    def _on_status(self, _msg: GoalStatusArray) -> None:
        self._last_status = time.monotonic()

    def _on_queue(self, msg: OrderQueue) -> None:
        self.queueReceived.emit(queue_from_message(msg))

    def _on_robot(self, msg: RobotState) -> None:
        frame = msg.header.frame_id.lstrip("/")
        if frame and frame != self.p.map_frame:
            rospy.logwarn_throttle(10.0, f"chefbot_gui: {msg.name}'s state in frame {frame!r}, "
                                         f"expected {self.p.map_frame!r}: ignored")
            return
        if not msg.name:
            rospy.logwarn_throttle(10.0, "chefbot_gui: a RobotState without a name: ignored")
            return
        self.robotReceived.emit(report_from_message(msg))

    def _on_map(self, msg: OccupancyGrid) -> None:
        try:
            grey, grid = grid_from_message(msg)
        except ValueError as e:
            rospy.logwarn(f"chefbot_gui: map ignored: {e}")
            return
        self.mapReceived.emit(grey, grid)
