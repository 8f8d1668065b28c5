"""ROS glue shared by the navigation nodes (imports rospy/tf2): timers that survive time jumping
back and exceptions (:func:`periodic`), a ``diagnostics`` publisher (:class:`Diagnostics`), planar
tf lookups (:class:`PlanarTf`), a wall-clock wait for an action server (:func:`wait_for_action_server`),
a SimpleActionClient without its send_goal race (:class:`GoalClient`)."""
from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from functools import partial
from typing import Any

import actionlib
import rospy
import tf2_ros
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from nav_msgs.msg import OccupancyGrid
from nav_msgs.srv import GetMap

from chefbot_common.geometry import Pose2D
from chefbot_common.params import ParamError, ParamSpec
from chefbot_navigation.health import TaskHealth
from chefbot_navigation.navigator import link_fault, pose_age_fault, stalest_link
from chefbot_navigation.ros_io import transform_to_pose2d

TF_ERRORS = (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException)


def periodic(rate_hz: float, fn: Callable[[], None], health: TaskHealth | None = None) -> threading.Thread:
    """Call ``fn`` at ``rate_hz`` (ROS time) in a daemon thread that survives time jumping back
    (a rospy.Timer thread dies with ROSTimeMovedBackwardsException) and exceptions of ``fn``:
    those are counted in ``health`` (``thread.health``), logged (throttled) and the loop goes on."""
    health = health or TaskHealth(getattr(fn, "__name__", "periodic task"))

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
            run_guarded(fn, health)

    thread = threading.Thread(target=loop, daemon=True, name=health.name)
    thread.health = health
    thread.start()
    return thread


def run_guarded(fn: Callable[[], None], health: TaskHealth) -> bool:
    """Call ``fn``; an exception (MemoryError included) is counted and logged, not raised. True if it ran.
    One raised while the node shuts down (its publishers closed under the running task: "publish() to a
    closed topic") is neither: nothing went wrong."""
    try:
        fn()
    except Exception as exc:   # noqa: BLE001 -- a background task must survive anything fn raises
        if rospy.is_shutdown():
            return False
        line = health.failed(exc, rospy.get_time())
        if line is not None:
            rospy.logerr(line)
        return False
    health.ok()
    return True


StatusFn = Callable[[float], tuple[int, str, dict[str, Any]]]


class Diagnostics:
    """Publishes ``diagnostics`` (diagnostic_msgs/DiagnosticArray) at ``rate_hz``: one status per
    registered source, each a function of the time (s) returning (level, message, key values)."""

    def __init__(self, prefix: str, rate_hz: float = 1.0) -> None:
        self.prefix = prefix
        self.sources: list[tuple[str, StatusFn]] = []
        self.pub = rospy.Publisher("diagnostics", DiagnosticArray, queue_size=5)
        self.health = TaskHealth(f"{prefix}: diagnostics")
        self.add("diagnostics publisher", self.health.status)
        self.rate_hz = rate_hz

    def add(self, name: str, fn: StatusFn) -> None:
        """Report ``fn``'s status under ``<prefix>: <name>``."""
        self.sources.append((name, fn))

    def add_task(self, thread: threading.Thread) -> None:
        """Report the health of a :func:`periodic` thread."""
        self.add(thread.health.name, thread.health.status)

    def start(self) -> threading.Thread:
        return periodic(self.rate_hz, self.publish, self.health)

    def publish(self) -> None:
        now = rospy.get_time()
        msg = DiagnosticArray()
        msg.header.stamp = rospy.Time.now()
        for name, fn in self.sources:
            level, text, values = fn(now)
            msg.status.append(DiagnosticStatus(level=level, name=f"{self.prefix}: {name}", message=text,
                                               hardware_id=rospy.get_name(),
                                               values=[KeyValue(str(k), str(v)) for k, v in values.items()]))
        self.pub.publish(msg)


def lookup_transform_wall(buffer: tf2_ros.Buffer, target: str, source: str, stamp: rospy.Time,
                          timeout_s: float):
    """``buffer.lookup_transform(target, source, stamp)``, waiting up to ``timeout_s`` of WALL time
    for the transform to arrive.  tf2_ros's own timeout counts ROS time: with a stopped /clock (a
    bag that ended, a paused simulation) it never runs out and the caller hangs.  Raises tf2's
    exceptions as lookup_transform does."""
    deadline = time.monotonic() + timeout_s
    while not buffer.can_transform(target, source, stamp) and time.monotonic() < deadline \
            and not rospy.is_shutdown():
        time.sleep(0.005)
    return buffer.lookup_transform(target, source, stamp)


def read_private_config(spec: ParamSpec, who: str) -> Any | None:
    """The config dataclass of ``spec`` (one of the node's ``PARAMS``) read from the parameter server;
    None after logging the ParamError (and printing it to stderr, which roslaunch shows)."""
    try:
        return spec.read(rospy.get_param)
    except ParamError as exc:
        rospy.logfatal(f"{who}: {exc}")
        print(f"{who}: {exc}", file=sys.stderr)
        return None


def static_map(who: str, service: str = "static_map") -> OccupancyGrid | None:
    """The map from map_server's GetMap ``service`` (waits for it); None, logged, if it fails.
    A shutdown while waiting (map_server died and roslaunch stops the launch) is no error."""
    try:
        rospy.wait_for_service(service)
        return rospy.ServiceProxy(service, GetMap)().map
    except (rospy.ROSInterruptException, rospy.ServiceException) as exc:
        if not rospy.is_shutdown():
            rospy.logerr(f"{who}: no map from service '{service}': {exc}")
        return None


class GoalClient(actionlib.SimpleActionClient):
    """``actionlib.SimpleActionClient`` (same API) without its race in ``send_goal``.

    SimpleActionClient stores the new goal's handle only after publishing the goal, and drops
    every transition whose handle is not the stored one.  A status that arrives in between (the
    server accepted or rejected at once) is dropped with "[ERROR] Got a transition callback on a
    goal handle that we're not tracking", and a quick reject or abort never reaches ``done_cb``.
    Here each goal's callbacks carry the goal's sequence number instead, so they are recognised
    before the handle is stored; a superseded goal's late callbacks are ignored quietly.
    """

    def __init__(self, ns: str, action_spec: type) -> None:
        super().__init__(ns, action_spec)
        self._seq = 0
        # the sequence check and the state it guards; reentrant: a done_cb may send the next goal
        self._track_lock = threading.RLock()

    def send_goal(self, goal, done_cb=None, active_cb=None, feedback_cb=None) -> None:
        with self._track_lock:
            self._seq += 1
            seq = self._seq
            self.stop_tracking_goal()
            self.done_cb, self.active_cb, self.feedback_cb = done_cb, active_cb, feedback_cb
            self.simple_state = actionlib.SimpleGoalState.PENDING
        # not under the lock: the status thread holds actionlib's list lock when it calls back
        gh = self.action_client.send_goal(goal, partial(self._transition, seq), partial(self._feedback, seq))
        with self._track_lock:
            if seq == self._seq:
                self.gh = gh

    def _transition(self, seq: int, gh) -> None:
        with self._track_lock:
            if seq != self._seq:
                return
            self.gh = gh
            self._handle_transition(gh)

    def _feedback(self, seq: int, gh, feedback) -> None:
        with self._track_lock:
            if seq != self._seq:
                return
            self.gh = gh
            self._handle_feedback(gh, feedback)


def wait_for_action_server(client, timeout_s: float) -> bool:
    """Wait up to ``timeout_s`` seconds of WALL time until ``client`` (a SimpleActionClient) sees its
    server: a status message arrived, the server subscribes to our goals, and our clock runs (under
    ``/use_sim_time`` ROS time is 0 until the first ``/clock`` message).  False on timeout or
    shutdown.  Not actionlib's ``wait_for_server``: its timeout counts ROS time, which under a fast
    simulation runs out before the client has connected, and never with a stalled /clock.

    Why the clock: actionlib stamps each goal id with ROS time, and a SimpleActionServer cancels
    ("RECALLED ... another goal was received") every goal stamped older than its current one, so a
    goal sent by a node that has no clock yet (stamp 0) is dropped at once: the ``deliver`` command
    started after another client's goal is the case (seen by hand with a client on wall-clock stamps)."""
    ac, deadline = client.action_client, time.monotonic() + timeout_s
    while ac.last_status_msg is None or ac.pub_goal.get_num_connections() == 0 or rospy.get_rostime().is_zero():
        if time.monotonic() > deadline or rospy.is_shutdown():
            return False
        time.sleep(0.05)
    return True


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
        """Latest pose of ``child`` if at most ``tolerance`` s old, else None and why (naming the
        stalest link of the chain and who publishes it, e.g. diff_tf's odom -> base_footprint)."""
        pose, stamp, why = self.lookup(child)
        now = rospy.get_time()
        if why:     # e.g. extrapolation into the past once a dead node's last transform left the cache
            stale = link_fault(self.stalest_link(child, now), tolerance, child)
            why = f"{stale}; {why}" if stale else why
        elif now - stamp > tolerance:
            why = pose_age_fault(now - stamp, tolerance, self.global_frame, child, self.stalest_link(child, now))
        return (None, why) if why else (pose, "")

    def stalest_link(self, child: str, now: float) -> tuple[str, str, str, float] | None:
        """The chain's oldest dynamic transform (see navigator.stalest_link); None if tf cannot say."""
        try:
            frames = yaml.safe_load(self.buffer.all_frames_as_yaml()) or {}
        except yaml.YAMLError:
            return None
        return stalest_link(frames, child, self.global_frame, now) if isinstance(frames, dict) else None

    def clear(self) -> None:
        """Forget every transform (time jumped back)."""
        self.buffer.clear()
