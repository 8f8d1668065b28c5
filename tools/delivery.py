"""Scripted table deliveries through move_base, as the restaurant's client would send them.

Used by `make demo` (tools/demo.py) and the delivery benchmark: a real
``actionlib.SimpleActionClient('move_base', MoveBaseAction)`` (GoalClient: the same without
its send_goal race) sends each table
pose of the shared tables YAML in turn, and every leg is measured against the
simulator's ground truth (``ground_truth/odom``): planned path length
(``move_base/make_plan``) and the time-optimal limit along it
(chefbot_navigation.time_limit.profile_limit: speed, acceleration and turn
limits), duration in sim time, final position/heading error, bumper contacts.
Over the whole route it also records, at 5 Hz sim time, the ground-truth pose
next to the localization estimate as move_base sees it (tf ``map`` ->
``base_footprint`` at the estimate's own stamp, the truth interpolated to that
stamp), and each leg's global plan (the ``make_plan`` result the leg's limit is
computed on): :meth:`DeliveryClient.trajectory`, plotted by tools/plots.py.
Needs a running simulation + navigation on the current ROS master
(``navigation_demo.launch``).
"""
from __future__ import annotations

import json
import math
import threading
import time
from collections import deque
from dataclasses import asdict, dataclass
from pathlib import Path

import actionlib
import numpy as np
import rospy
import tf2_ros
from actionlib_msgs.msg import GoalStatus
from geometry_msgs.msg import PoseStamped, Quaternion
from move_base_msgs.msg import MoveBaseAction, MoveBaseActionGoal, MoveBaseActionResult, MoveBaseGoal
from nav_msgs.msg import Odometry
from nav_msgs.srv import GetPlan
from plots import PlotError, pose_at, write_plots
from std_msgs.msg import Bool

from chefbot_common.geometry import Pose2D, quaternion_from_yaw, yaw_from_quaternion
from chefbot_navigation.ros_util import GoalClient, wait_for_action_server
from chefbot_navigation.time_limit import MotionLimits, profile_limit

MAX_SPEED = 0.35  # m/s, the robot's top speed (book requirement 0.25-0.35 m/s)
# the robot's limits as move_base's controller has them (param/move_base.yaml: max_vel_x,
# max_vel_theta, acc_lim_x, acc_lim_theta)
LIMITS = MotionLimits(v_max=MAX_SPEED, w_max=2.5, acc=0.8, dec=0.8, alpha=3.0)
SAMPLE_PERIOD_S = 0.2     # sim s between trajectory samples (5 Hz)
RESULT_GRACE = 2.0         # s wall: a terminal goal status whose result message does not follow
TRUTH_HISTORY = 100       # ground-truth messages kept to interpolate at the estimate's stamp (2 s at 50 Hz)


class TruthHistory:
    """The last ``size`` poses of ``ground_truth/odom`` (the simulator's oracle) as (t s, x m, y m, yaw rad)
    in the world, fed by :meth:`add`; :meth:`at` interpolates them at a stamp (``plots.pose_at``)."""

    def __init__(self, size: int = TRUTH_HISTORY) -> None:
        self._lock = threading.Lock()
        self._poses: deque[tuple[float, float, float, float]] = deque(maxlen=size)

    def add(self, msg: Odometry) -> None:
        p = msg.pose.pose
        yaw = yaw_from_quaternion(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)
        with self._lock:
            self._poses.append((msg.header.stamp.to_sec(), p.position.x, p.position.y, yaw))

    def last_stamp(self) -> float | None:
        """The newest pose's stamp (sim s), None before the first."""
        with self._lock:
            return self._poses[-1][0] if self._poses else None

    def at(self, t: float) -> tuple[float, float, float] | None:
        """(x, y, yaw) at sim time ``t``, or None outside the poses kept."""
        with self._lock:
            poses = list(self._poses)
        return pose_at(poses, t)


def latest_pose(buffer: tf2_ros.Buffer, frame: str = "map",
                child: str = "base_footprint") -> tuple[float, Pose2D] | None:
    """The latest ``frame -> child`` in ``buffer`` with its stamp (sim s), or None when tf has none."""
    try:
        tfm = buffer.lookup_transform(frame, child, rospy.Time(0))
    except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException):
        return None
    tr, q = tfm.transform.translation, tfm.transform.rotation
    return tfm.header.stamp.to_sec(), Pose2D(tr.x, tr.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))


@dataclass
class Leg:
    name: str
    ok: bool
    state: str
    text: str
    planned_m: float       # length of the global plan from the start pose (m)
    seconds: float         # sim time from goal to result (s)
    limit_s: float         # time-optimal limit along the plan: speed/acceleration profile + turns (s)
    xy_error: float        # final ground-truth distance to the goal pose (m)
    yaw_error: float       # final ground-truth heading error (rad)
    bumps: int             # bumper contacts during the leg
    loc_error: float = float("nan")  # final localization error: map->base_footprint (in the world) vs truth (m)
    estimate: tuple[float, float, float] | None = None  # final map->base_footprint (x m, y m, yaw rad)
    truth: tuple[float, float, float] | None = None     # final ground truth, world frame (x m, y m, yaw rad)

    def line(self) -> str:
        if self.state != "SUCCEEDED":
            return f"{self.name}: FAILED ({self.state}: {self.text})"
        ratio = self.seconds / self.limit_s if self.limit_s > 0 else float("nan")
        return (f"{self.name}: {self.planned_m:.2f} m planned, {self.seconds:.1f} s "
                f"(limit {self.limit_s:.1f} s, {ratio:.2f}x), final error {self.xy_error * 100:.1f} cm / "
                f"{math.degrees(self.yaw_error):.1f} deg, localization error {self.loc_error * 100:.1f} cm, "
                f"bumps {self.bumps}")

    def as_dict(self) -> dict:
        return asdict(self)


class DeliveryClient:
    """A move_base client with ground-truth bookkeeping (call after rospy.init_node).

    Goals are in the ``map`` frame, ground truth in the simulator's world frame;
    ``map_in_world`` (the map frame's pose in the world, m/rad; identity for the
    world raster, from the tables file's ``map_in_world`` for a SLAM map) carries
    goals into the world for the final-error check: a test oracle.  ``ns`` names a robot of a
    fleet (``chefbot2``: its topics under ``/chefbot2``, its frames prefixed ``chefbot2/``).
    """

    def __init__(self, map_in_world: Pose2D | None = None, ns: str = "") -> None:
        self.map_in_world = map_in_world or Pose2D()
        ns = ns.strip("/")
        self.pre = f"/{ns}/" if ns else ""
        self.base_frame = f"{ns}/base_footprint" if ns else "base_footprint"
        self._lock = threading.Lock()
        self.truth: Odometry | None = None
        self.bumps = 0
        self._bumping = False
        self._history = TruthHistory()
        self._samples: list[tuple[float, tuple[float, float, float], tuple[float, float, float] | None]] = []
        self._legs: list[dict] = []
        rospy.Subscriber(self.pre + "ground_truth/odom", Odometry, self._on_truth, queue_size=1, tcp_nodelay=True)
        rospy.Subscriber(self.pre + "bumper", Bool, self._on_bumper, queue_size=10)
        self.client = GoalClient(self.pre + "move_base", MoveBaseAction)
        self.tf_buffer = tf2_ros.Buffer()
        self._tf_listener = tf2_ros.TransformListener(self.tf_buffer)
        self._timer = rospy.Timer(rospy.Duration(SAMPLE_PERIOD_S), self._sample)
        # goals other clients (the GUI) send, and their results: observe() (subscribed on first use)
        self._goals: list[tuple[str, rospy.Time, Pose2D]] = []
        self._results: dict[str, tuple[int, str]] = {}
        self._observing = False

    def _estimate_stamped(self) -> tuple[float, Pose2D] | None:
        """The localization's latest map->base_footprint with its stamp (sim s), or None when tf has none."""
        return latest_pose(self.tf_buffer, child=self.base_frame)

    def estimate(self) -> Pose2D | None:
        """The localization's latest map->base_footprint, or None when tf has none."""
        stamped = self._estimate_stamped()
        return stamped[1] if stamped else None

    def _on_truth(self, msg: Odometry) -> None:
        with self._lock:
            self.truth = msg
        self._history.add(msg)

    def _sample(self, _event: rospy.timer.TimerEvent) -> None:
        """One trajectory sample: the estimate (tf, latest) and the truth at the estimate's stamp,
        carried into the map frame (``map_in_world``)."""
        stamped = self._estimate_stamped()
        t_last = self._history.last_stamp()
        if t_last is None:
            return
        t, estimate = (t_last, None) if stamped is None else stamped  # no localization yet: truth alone
        truth = self._history.at(t)
        if truth is None:
            return
        here = self.map_in_world.inverse().compose(Pose2D(*truth))   # world -> map frame
        with self._lock:
            if self._samples and t <= self._samples[-1][0]:
                return          # nothing new (the sim is paused or the tf is stale)
            self._samples.append((t, (here.x, here.y, here.yaw),
                                  None if estimate is None else (estimate.x, estimate.y, estimate.yaw)))

    def trajectory(self, map_file: str) -> dict:
        """The route's record so far (JSON-ready): samples, legs with plans, and the map they are drawn on.

        ``samples``: ``t`` (sim s), ``truth`` and ``estimate`` as [x m, y m, yaw rad] in the map
        frame (``estimate`` null before localization is up); ``legs``: name, goal [x, y, yaw],
        ``t_start``/``t_end`` (sim s), ``plan`` [[x, y], ...] (m) from the leg's start.
        """
        with self._lock:
            samples, legs = list(self._samples), [dict(leg) for leg in self._legs]

        def r(v):
            return None if v is None else [round(float(a), 4) for a in v]
        return {
            "map_file": str(map_file),
            "frame": "map",
            "estimate_source": "tf map -> base_footprint, as move_base sees it",
            "truth_source": "ground_truth/odom (simulator oracle), carried into the map frame",
            "map_in_world": [self.map_in_world.x, self.map_in_world.y, self.map_in_world.yaw],
            "period_s": SAMPLE_PERIOD_S,
            "samples": {"t": [round(s[0], 3) for s in samples], "truth": [r(s[1]) for s in samples],
                        "estimate": [r(s[2]) for s in samples]},
            "legs": legs,
        }

    def _on_bumper(self, msg: Bool) -> None:
        with self._lock:
            if msg.data and not self._bumping:
                self.bumps += 1
            self._bumping = msg.data

    def _truth_pose(self) -> Pose2D:
        """The latest ground-truth pose (world frame); call with the lock held."""
        p = self.truth.pose.pose
        yaw = yaw_from_quaternion(*(getattr(p.orientation, k) for k in "xyzw"))
        return Pose2D(p.position.x, p.position.y, yaw)

    def _truth_in_map(self) -> Pose2D:
        """The latest ground-truth pose in the map frame (world -> map through ``map_in_world``)."""
        with self._lock:
            truth = self._truth_pose()
        return self.map_in_world.inverse().compose(truth)

    def wait_ready(self, timeout: float) -> None:
        """Wait (wall clock) for ground truth and the move_base server."""
        deadline = time.monotonic() + timeout
        while self.truth is None:
            if time.monotonic() > deadline or rospy.is_shutdown():
                raise TimeoutError("no ground_truth/odom from the simulator")
            time.sleep(0.05)
        if not wait_for_action_server(self.client, max(0.0, deadline - time.monotonic())):   # wall clock
            raise TimeoutError("move_base action server not up")
        rospy.wait_for_service(self.pre + "move_base/make_plan", timeout=max(1.0, deadline - time.monotonic()))
        self.make_plan = rospy.ServiceProxy(self.pre + "move_base/make_plan", GetPlan)

    def wait_localized(self, timeout: float, tolerance: float = 0.3) -> None:
        """Wait (wall clock) until the localization's estimate is within ``tolerance`` m of the truth: a
        fleet robot's amcl starts at the map origin until fleet_member's initial pose arrives, and a goal
        sent before that was planned from inside a wall and aborted as unreachable."""
        deadline = time.monotonic() + timeout
        while True:
            est = self.estimate()
            here = self._truth_in_map()
            if est is not None and math.hypot(est.x - here.x, est.y - here.y) <= tolerance:
                return
            if time.monotonic() > deadline or rospy.is_shutdown():
                where = "none" if est is None else f"({est.x:.2f}, {est.y:.2f})"
                raise TimeoutError(f"{self.pre or '/'}: localization estimate {where} not within {tolerance} m "
                                   f"of the robot at ({here.x:.2f}, {here.y:.2f}) after {timeout:.0f} s")
            time.sleep(0.1)

    def planned_path(self, x: float, y: float, yaw: float) -> tuple[np.ndarray, float]:
        """The global plan from the robot's pose to (x, y, yaw): points (N, 2) m and the robot's yaw."""
        here = self._truth_in_map()
        start = PoseStamped()
        start.header.frame_id = "map"
        start.pose.position.x, start.pose.position.y = here.x, here.y
        start.pose.orientation = Quaternion(*quaternion_from_yaw(here.yaw))
        goal = PoseStamped()
        goal.header.frame_id = "map"
        goal.pose.position.x, goal.pose.position.y = x, y
        goal.pose.orientation = Quaternion(*quaternion_from_yaw(yaw))
        start_yaw = here.yaw
        try:
            plan = self.make_plan(start=start, goal=goal, tolerance=0.0).plan.poses
        except rospy.ServiceException:
            return np.zeros((0, 2)), start_yaw
        return np.array([(p.pose.position.x, p.pose.position.y) for p in plan]).reshape(-1, 2), start_yaw

    def _plan_leg(self, x: float, y: float, yaw: float) -> tuple[np.ndarray, float, float]:
        """The leg's global plan from here (N, 2), its length (m) and time-optimal limit (s)."""
        pts, start_yaw = self.planned_path(x, y, yaw)
        planned = float(np.sum(np.hypot(*np.diff(pts, axis=0).T))) if len(pts) > 1 else float("nan")
        limit = profile_limit(pts, LIMITS, start_yaw, yaw) if len(pts) > 1 else float("nan")
        return pts, planned, limit

    def deliver(self, name: str, x: float, y: float, yaw: float, timeout_wall: float) -> Leg:
        """Drive to one pose; measure against ground truth."""
        pts, planned, limit = self._plan_leg(x, y, yaw)
        goal = MoveBaseGoal()
        goal.target_pose.header.frame_id = "map"
        goal.target_pose.header.stamp = rospy.Time.now()
        goal.target_pose.pose.position.x, goal.target_pose.pose.position.y = x, y
        goal.target_pose.pose.orientation = Quaternion(*quaternion_from_yaw(yaw))
        with self._lock:
            bumps0 = self.bumps
        t0 = rospy.Time.now()
        self.client.send_goal(goal)
        # Poll the goal state against a wall-clock deadline: wait_for_result's timeout counts
        # ROS time, which would not run out if the simulation (and its /clock) stalled.
        # Finished means the *result* arrived (simple state DONE), not only a terminal status: the
        # status array can come first, and the next goal must not be sent before the result is in.
        # (GoalClient: SimpleActionClient without its send_goal race, which logged "[ERROR] Got a
        # transition callback on a goal handle that we're not tracking".)  A result that never
        # follows its terminal status is waited for RESULT_GRACE s, then the status counts.
        deadline = time.monotonic() + timeout_wall
        finished, terminal_since = False, None
        while not finished and time.monotonic() < deadline and not rospy.is_shutdown():
            time.sleep(0.05)
            if self.client.simple_state == actionlib.SimpleGoalState.DONE:
                finished = True
            elif self.client.get_state() not in (GoalStatus.PENDING, GoalStatus.ACTIVE):
                terminal_since = terminal_since or time.monotonic()
                finished = time.monotonic() - terminal_since > RESULT_GRACE
        if not finished:
            self.client.cancel_goal()
            state, text = "TIMEOUT", f"no result within {timeout_wall:.0f} s wall time"
        else:
            state = GoalStatus.to_string(self.client.get_state())
            text = self.client.get_goal_status_text()
        return self._leg(name, (x, y, yaw), pts, planned, limit, t0, state, text, bumps0)

    def _on_goal(self, msg: MoveBaseActionGoal) -> None:
        p = msg.goal.target_pose.pose
        yaw = yaw_from_quaternion(p.orientation.x, p.orientation.y, p.orientation.z, p.orientation.w)
        with self._lock:
            self._goals.append((msg.goal_id.id, rospy.Time.now(), Pose2D(p.position.x, p.position.y, yaw)))

    def _on_result(self, msg: MoveBaseActionResult) -> None:
        with self._lock:
            self._results[msg.status.goal_id.id] = (msg.status.status, msg.status.text)

    def observe(self, name: str, x: float, y: float, yaw: float, timeout_wall: float) -> Leg:
        """Measure one leg that another client drives (the GUI): wait for its goal to (x, y, yaw) on
        ``move_base/goal``, then for that goal's result; the same figures as :meth:`deliver`."""
        if not self._observing:
            self._observing = True
            rospy.Subscriber(self.pre + "move_base/goal", MoveBaseActionGoal, self._on_goal, queue_size=10)
            rospy.Subscriber(self.pre + "move_base/result", MoveBaseActionResult, self._on_result, queue_size=10)
        deadline = time.monotonic() + timeout_wall
        goal = None
        while goal is None and time.monotonic() < deadline and not rospy.is_shutdown():
            with self._lock:
                for k, (gid, t_sent, pose) in enumerate(self._goals):
                    dyaw = abs(math.remainder(pose.yaw - yaw, 2 * math.pi))
                    if math.hypot(pose.x - x, pose.y - y) < 0.01 and dyaw < 0.01:
                        goal = (gid, t_sent)
                        bumps0 = self.bumps
                        del self._goals[:k + 1]
                        break
            time.sleep(0.05)
        if goal is None:
            nan = float("nan")
            return Leg(name=name, ok=False, state="TIMEOUT", text=f"no goal to {name} within {timeout_wall:.0f} s "
                       "wall time", planned_m=nan, seconds=nan, limit_s=nan, xy_error=nan, yaw_error=nan, bumps=0)
        gid, t0 = goal
        pts, planned, limit = self._plan_leg(x, y, yaw)
        result = None
        while result is None and time.monotonic() < deadline and not rospy.is_shutdown():
            with self._lock:
                result = self._results.pop(gid, None)
            time.sleep(0.05)
        state, text = ((GoalStatus.to_string(result[0]), result[1]) if result is not None else
                       ("TIMEOUT", f"no result within {timeout_wall:.0f} s wall time"))
        return self._leg(name, (x, y, yaw), pts, planned, limit, t0, state, text, bumps0)

    def _leg(self, name: str, goal_pose: tuple[float, float, float], pts: np.ndarray, planned: float, limit: float,
             t0: rospy.Time, state: str, text: str, bumps0: int) -> Leg:
        """The finished leg measured against ground truth (and recorded for the trajectory)."""
        x, y, yaw = goal_pose
        t1 = rospy.Time.now()
        seconds = (t1 - t0).to_sec()
        with self._lock:
            p = self._truth_pose()
            bumps = self.bumps - bumps0
            self._legs.append({"name": name, "goal": [x, y, yaw], "t_start": round(t0.to_sec(), 3),
                               "t_end": round(t1.to_sec(), 3), "plan": np.round(pts, 3).tolist()})
        est = self.estimate()
        loc = self.map_in_world.compose(est).distance(p) if est else float("nan")
        target = self.map_in_world.compose(Pose2D(x, y, yaw))   # the goal in the world frame
        xy = math.hypot(p.x - target.x, p.y - target.y)
        dyaw = abs(math.remainder(p.yaw - target.yaw, 2 * math.pi))
        return Leg(name=name, ok=state == "SUCCEEDED", state=state, text=text, planned_m=planned,
                   seconds=seconds, limit_s=limit, xy_error=xy, yaw_error=dyaw, bumps=bumps,
                   loc_error=loc, estimate=(est.x, est.y, est.yaw) if est else None, truth=(p.x, p.y, p.yaw))


def launch_map_file(roslaunch_cmd: list[str]) -> str:
    """The map YAML the map_server of a ``roslaunch [--opts] PKG FILE arg:=value ...`` command serves
    (its launch default included), resolved by roslaunch's own loader; "" if no map_server in it."""
    import roslaunch.config
    import roslaunch.rlutil

    words = [w for w in roslaunch_cmd[1:] if not w.startswith("--")]
    launch_args = [w for w in words if ":=" in w]
    try:
        path = roslaunch.rlutil.resolve_launch_arguments([w for w in words if ":=" not in w])[0]
        config = roslaunch.config.load_config_default([(path, launch_args)], None, verbose=False)
    except roslaunch.core.RLException as exc:
        rospy.logwarn("cannot tell the map file of %s: %s", " ".join(roslaunch_cmd), exc)
        return ""
    return next((n.args.split()[0] for n in config.nodes if n.type == "map_server" and n.args.strip()), "")


def save_route_report(trajectory: dict, out_dir: Path, legs: list[Leg], summary: dict) -> list[str]:
    """Write ``delivery.json`` (``summary`` + the legs), ``trajectory.json`` and the plots (tools/plots.py)
    into ``out_dir``; one line per file written, or the reason the plots could not be drawn."""
    out_dir.mkdir(parents=True, exist_ok=True)
    (out_dir / "delivery.json").write_text(json.dumps({**summary, "legs": [leg.as_dict() for leg in legs]},
                                                      indent=2) + "\n")
    path = out_dir / "trajectory.json"
    path.write_text(json.dumps(trajectory, separators=(",", ":")) + "\n")
    lines = [f"trajectory: {path} ({len(trajectory['samples']['t'])} samples)"]
    try:
        lines += [f"plot: {p}" for p in write_plots(out_dir)]
    except PlotError as exc:
        lines.append(f"plots NOT written: {exc}")
    return lines
