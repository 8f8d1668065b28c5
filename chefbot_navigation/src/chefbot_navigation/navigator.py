"""move_base's decision logic without ROS: plan, control, recover, succeed or abort (pure).

The node calls :meth:`Navigator.step` at the controller rate with the time
(s), the robot pose in the map frame, and gets a velocity command plus an
outcome when the goal is finished.  Planning, control and recovery follow
move_base's state machine:

* PLANNING: plan on the global costmap.  Goals inside an obstacle, in
  unknown space, off the map or unreachable abort at once, after one
  'clear costmaps' retry (the blocking cells may be stale scan marks).
  Other planner failures -- and a goal that only the sensors' marks block,
  free on the map -- are retried until ``planner_patience``.  When another
  robot of a fleet (the costmap's robots layer) is the only way, the goal is
  planned through it (its cells cost 252): the robot drives up behind it and
  waits for it to move on (or for one of the two to be told to give way).
* CONTROLLING: the local controller follows the plan; the plan is renewed
  at ``planner_frequency`` and at once when an inscribed/lethal cell appears
  on the remaining path within ``path_check_distance``.  A controller that
  finds no safe command for ``controller_patience``, or a robot that moves
  less than ``oscillation_distance`` in ``oscillation_timeout`` (final yaw
  alignment excepted), triggers recovery.
* RECOVERING: the behaviours run in order -- clear the scan obstacles,
  rotate in place once around, back off -- each followed by a fresh plan;
  when the last one has run and the robot is still stuck the goal aborts.
* No usable pose (stale tf, no recent scan: the node passes ``pose=None``
  and why): stop; the goal aborts after ``controller_patience`` without one.
* HELD (:meth:`Navigator.set_hold`, a fleet's traffic rule: wait outside a single-lane zone another
  robot holds): once the goal has a plan, stop and wait as long as the hold lasts; no patience runs
  out and nothing is recovered meanwhile, and every timer starts afresh when it ends.
* RETREATING (:meth:`Navigator.request_retreat`, a fleet's mutual block: this robot gives way):
  reverse along the way the robot came (its *trail*: the poses it drove through, the last
  ``TRAIL_MAX`` x ``TRAIL_SPACING`` m, kept across goals; driving back along it shortens it) up to
  ``retreat_distance``, stopping early if anything is behind it, then plan afresh.  A hold does not
  stop a retreat.
* ESCAPING: the path leaves behind the robot but it has no room to turn on the spot (a dead-end aisle,
  the mouth of a gap a refused goal left it in; the controller blocked by the static map, or starting
  to back out along the new path): reverse along the trail -- the way it came, known to be passable --
  ``ESCAPE_BEYOND`` past the first place where a whole turn on the spot is free (at most
  ``escape_distance``; stopping early if anything is behind it or the trail ends), then plan afresh.
  The escape may brush what the robot touches where it stands (``without_touched``: a robot wedged
  in a gap's mouth).  At most ``MAX_ESCAPES`` per goal; after that the controller backs out along the
  path itself, and a block counts as a passage narrower than the robot (``narrow_patience``).
  A block by the static map while another robot is within ``SQUEEZE_NEAR`` (or was, within
  ``narrow_patience``) is an escape after ``SQUEEZE_WAIT``, not a narrow passage: planned round that
  robot, this one was squeezed against a chair or a wall.

Also here, pure: the node's own parameters (:class:`NodeParams`, read with
:func:`read_move_base_params`), goal checking (:func:`parse_goal`) and the
scan-age check (:func:`scan_fault`).
"""
from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from chefbot_common.geometry import Pose2D, QuaternionError, wrap_angle, yaw_from_quaternion
from chefbot_common.map_io import MAX_MAP_CELLS
from chefbot_common.params import private_spec
from chefbot_navigation.controller import (
    BACKING_OUT,
    CONTROLLERS,
    NO_ROOM_TO_TURN,
    ControllerParams,
    LocalController,
    make_controller,
)
from chefbot_navigation.costmap import INSCRIBED, LETHAL, CostmapParams, LayeredCostmap
from chefbot_navigation.footprint import Footprint
from chefbot_navigation.planners import PLANNERS, GlobalPlanner, Plan, PlannerParams, PlanningError, make_planner

TRAIL_SPACING = 0.05    # m between the trail's poses
TRAIL_MAX = 80          # trail poses kept (4 m)
TRAIL_JUMP = 0.5        # m: a pose this far from the last one is a relocalisation -- the trail restarts
RETREAT_LOOKAHEAD = 0.25  # m back along the trail the retreat steers to
RETREAT_SPEED = 0.1     # m/s
MAX_ESCAPES = 2         # escapes (reversing along the trail to room to turn) per goal
ESCAPE_BEYOND = 0.3     # m an escape reverses on after the first place with room to turn
ESCAPE_TURN_S = 6.0     # s an escape may turn on the spot to put its back to the way it came
SQUEEZE_NEAR = 1.0      # m: another robot this near (its footprint) when the map blocks the path: squeezed by it
SQUEEZE_WAIT = 2.0      # s blocked so before a robot squeezed against the map backs out the way it came

GOAL_ERRORS = ("goal_off_map", "goal_in_obstacle", "goal_too_close", "goal_unknown", "no_path", "start_off_map")
RECOVERIES = ("clear_costmaps", "rotate", "back_off")


@dataclass(frozen=True)
class NavigatorParams:
    """move_base-level tunables (s, m, Hz)."""

    planner_frequency: float = 1.0        # Hz, periodic replanning while moving (0 = only when needed)
    planner_patience: float = 5.0         # s without a valid plan before recovery
    controller_patience: float = 15.0     # s without a valid command before recovery
    oscillation_timeout: float = 20.0     # s, 0 disables
    oscillation_distance: float = 0.2     # m the robot must move within oscillation_timeout
    recovery_behavior_enabled: bool = True
    path_check_distance: float = 2.5      # m of remaining path checked for new obstacles every step
    local_window: float = 3.0             # m, side of the rolling local costmap
    back_off_distance: float = 0.15       # [m] how far the back-off recovery reverses (> 0)
    back_off_speed: float = 0.08          # [m/s] reverse speed of the back-off recovery (> 0)
    rotate_speed: float = 1.0             # rad/s of the rotate recovery
    narrow_patience: float = 5.0          # s blocked by the static map (a passage narrower than the robot) -> abort
    replan_hysteresis: float = 0.3        # m: until the robot moved this far from where its clear path was made, a
                                          # periodic replan replaces the path only if this much shorter
    retreat_distance: float = 0.8         # [m] a retreat reverses this far along the way the robot came (> 0)
    give_way_wait: float = 20.0           # [s] after a retreat, the robot waits while another robot is its only
                                          # way, at most this long, before it plans through it again (> 0)
    escape_distance: float = 3.0          # [m] with no room to turn, the robot reverses at most this far along
                                          # the way it came to find room (> 0)

    def __post_init__(self) -> None:
        if self.planner_frequency < 0.0:
            raise ValueError(f"planner_frequency must be >= 0 Hz, got {self.planner_frequency}")
        for name in ("planner_patience", "controller_patience", "oscillation_distance", "path_check_distance",
                     "local_window", "back_off_distance", "back_off_speed", "rotate_speed",
                     "narrow_patience", "retreat_distance", "give_way_wait", "escape_distance"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.oscillation_timeout < 0.0:
            raise ValueError(f"oscillation_timeout must be >= 0 s, got {self.oscillation_timeout}")
        if not self.replan_hysteresis >= 0.0:
            raise ValueError(f"replan_hysteresis must be >= 0 m, got {self.replan_hysteresis}")


def path_length(points: np.ndarray) -> float:
    """Length (m) of a polyline (N, 2)."""
    return float(np.sum(np.hypot(*np.diff(points, axis=0).T))) if len(points) > 1 else 0.0


def remaining_length(points: np.ndarray, x: float, y: float) -> float:
    """Length (m) still to drive along ``points`` from (x, y): to its nearest point, then along it."""
    d = np.hypot(points[:, 0] - x, points[:, 1] - y)
    i = int(np.argmin(d))
    return float(d[i]) + path_length(points[i:])


@dataclass(frozen=True)
class NodeParams:
    """move_base node-level params (s, Hz, frame names)."""

    controller_frequency: float = 10.0      # Hz
    global_frame: str = "map"               # frame of plans, costmaps and the robot pose; goals in another frame
                                            # are transformed into it by tf
    robot_base_frame: str = "base_footprint"  # robot frame: its pose is global_frame -> this in tf (the URDF
                                              # footprint is taken in it)
    transform_tolerance: float = 0.5        # s, older robot pose = stale -> stop
    sensor_timeout: float = 1.0             # s without scan -> stop (0 disables the check)
    base_global_planner: str = "hierarchical"
    base_local_planner: str = "regulated_pure_pursuit"  # local controller; only regulated_pure_pursuit exists
    zero_quaternion_policy: str = "identity"   # all-zero (unset) quaternion: identity | ignore_yaw | reject
    global_publish_frequency: float = 1.0   # Hz, global costmap topic
    local_publish_frequency: float = 2.0    # Hz, local costmap topic
    max_map_cells: int = MAX_MAP_CELLS      # cells; a bigger `map` message is refused (4000 x 4000)

    def __post_init__(self) -> None:
        if not self.max_map_cells >= 1:
            raise ValueError(f"max_map_cells must be >= 1, got {self.max_map_cells}")
        if not self.controller_frequency >= 1.0:
            raise ValueError(f"controller_frequency must be >= 1 Hz, got {self.controller_frequency}")
        if not self.transform_tolerance > 0.0:
            raise ValueError(f"transform_tolerance must be > 0 s, got {self.transform_tolerance}")
        if self.sensor_timeout < 0.0:
            raise ValueError(f"sensor_timeout must be >= 0 s, got {self.sensor_timeout}")
        if self.base_global_planner not in PLANNERS:
            raise ValueError(f"base_global_planner must be one of {sorted(PLANNERS)}, got "
                             f"{self.base_global_planner!r}")
        if self.base_local_planner not in CONTROLLERS:
            raise ValueError(f"base_local_planner must be one of {sorted(CONTROLLERS)}, got "
                             f"{self.base_local_planner!r}")
        if self.zero_quaternion_policy not in ("identity", "ignore_yaw", "reject"):
            raise ValueError(f"zero_quaternion_policy must be identity, ignore_yaw or reject, got "
                             f"{self.zero_quaternion_policy!r}")
        if not (self.global_frame and self.robot_base_frame):
            raise ValueError("global_frame and robot_base_frame must be non-empty")
        if self.global_publish_frequency < 0.0 or self.local_publish_frequency < 0.0:
            raise ValueError("global_publish_frequency and local_publish_frequency must be >= 0 Hz")


# move_base's params in the layout of param/move_base.yaml: read by read_move_base_params, listed in the node's PARAMS
MOVE_BASE_PARAMS = (
    private_spec(NodeParams),
    private_spec(NavigatorParams),
    private_spec(ControllerParams, "controller/", xy_goal_tolerance="~xy_goal_tolerance",
                 yaw_goal_tolerance="~yaw_goal_tolerance", controller_frequency="~controller_frequency"),
    private_spec(CostmapParams, "costmap/"),
    private_spec(PlannerParams, "planner/"),
)


def read_move_base_params(get: Callable[[str, Any], Any]) -> tuple[NodeParams, NavigatorParams, ControllerParams,
                                                                    CostmapParams, PlannerParams]:
    """All move_base params (:data:`MOVE_BASE_PARAMS`); ParamError names a bad one."""
    return tuple(spec.read(get) for spec in MOVE_BASE_PARAMS)


class GoalError(ValueError):
    """A goal that cannot be used; the message is the abort text."""


def parse_goal(position: tuple[float, float, float], orientation: tuple[float, float, float, float],
               zero_policy: str) -> tuple[Pose2D, bool]:
    """Planar goal (m, m, rad) in its own frame from a pose, and whether it asks for a final yaw.

    Raises :class:`GoalError` for a non-finite position or an unusable quaternion
    (``zero_policy`` as :func:`chefbot_common.geometry.yaw_from_quaternion`).
    """
    x, y, z = position
    if not all(math.isfinite(v) for v in (x, y, z)):
        raise GoalError(f"goal position ({x}, {y}) is not finite")
    try:
        yaw = yaw_from_quaternion(*orientation, zero_policy)
    except QuaternionError as exc:
        raise GoalError(f"invalid goal orientation: {exc}") from None
    return Pose2D(x, y, yaw or 0.0), yaw is not None


def costmap_params_for(cost: CostmapParams, footprint: Footprint | None) -> CostmapParams:
    """``cost`` with the inscribed/circumscribed radii of ``footprint`` (unchanged when None)."""
    if footprint is None:
        return cost
    inscribed, circumscribed = footprint.inscribed_radius, footprint.circumscribed_radius
    return dataclasses.replace(cost, robot_radius=inscribed, circumscribed_radius=circumscribed,
                               inflation_radius=max(cost.inflation_radius, circumscribed))


def build_navigator(occ, node: NodeParams, nav: NavigatorParams, ctrl: ControllerParams, cost: CostmapParams,
                    plan: PlannerParams, old: Navigator | None, t: float,
                    footprint: Footprint | None = None) -> tuple[LayeredCostmap, Navigator]:
    """Costmap and navigator for a (new) map; the goal of ``old`` carries over, restarted at ``t`` (s).

    With a ``footprint`` the costmap uses its inscribed radius (cost 253) and the controller checks
    the polygon (points every half cell) against lethal cells."""
    cost = costmap_params_for(cost, footprint)
    layers = LayeredCostmap(occ, cost)
    controller = make_controller(node.base_local_planner, ctrl)
    if footprint is not None and hasattr(controller, "set_footprint"):
        controller.set_footprint(footprint.samples(0.5 * occ.info.resolution))
    navigator = Navigator(nav, ctrl, make_planner(node.base_global_planner, plan, cost.robot_radius),
                          controller, layers)
    if old is not None and old.goal is not None:
        navigator.set_goal(old.goal, t)
    return layers, navigator


def pose_age_fault(age: float, tolerance: float, parent: str, child: str,
                   link: tuple[str, str, str, float] | None = None) -> str:
    """Why a robot pose ``age`` s old is too stale to drive on ('' when within ``tolerance`` s).

    ``link`` (parent, child, broadcaster, age s), from :func:`stalest_link`, names the transform of
    the chain that went stale -- e.g. ``map -> odom`` of a localization node that died."""
    if age <= tolerance:
        return ""
    text = f"transform {parent} -> {child} is {age:.2f} s old (transform_tolerance {tolerance} s)"
    stale = link_fault(link, tolerance, child)
    return f"{text}; {stale}" if stale else text


def link_fault(link: tuple[str, str, str, float] | None, tolerance: float, base: str = "") -> str:
    """``stale link map -> odom (from /amcl), not updated for 3.20 s`` when ``link`` (see
    :func:`stalest_link`) is older than ``tolerance`` s, else ''.  Also explains a failed lookup:
    once the dead link's last transform falls out of the tf cache, tf2 reports only an
    extrapolation error.  A stale link ending in the robot's ``base`` frame is the odometry's:
    the text says so (drive, board link or encoders down)."""
    if link is None or link[3] <= tolerance:
        return ""
    hint = " (no odometry: drive, board link or encoders down?)" if base and link[1] == base else ""
    return f"stale link {link[0]} -> {link[1]} (from {link[2]}), not updated for {link[3]:.2f} s{hint}"


def stalest_link(frames: dict[str, Any], child: str, root: str,
                 now: float) -> tuple[str, str, str, float] | None:
    """The oldest non-static transform on the tf chain ``root`` ... -> ``child``.

    ``frames`` is tf2's ``all_frames_as_yaml()`` parsed: frame -> {parent, broadcaster,
    most_recent_transform (s; 0 for static transforms)}.  Returns (parent, child, broadcaster,
    age s at ``now``), or None when the chain has no dynamic link or is broken."""
    oldest: tuple[str, str, str, float] | None = None
    frame, seen = child, set()
    while frame != root and frame in frames and frame not in seen:
        seen.add(frame)
        info = frames[frame] or {}
        parent, stamp = str(info.get("parent", "")), float(info.get("most_recent_transform", 0.0) or 0.0)
        if stamp > 0.0 and (oldest is None or now - stamp > oldest[3]):
            oldest = (parent, frame, str(info.get("broadcaster", "unknown")), now - stamp)
        frame = parent
    return oldest


def scan_fault(now: float, last_scan_time: float | None, timeout: float) -> str:
    """Why the scan is too old to drive on (s); '' when fresh or the check is disabled (timeout 0)."""
    if timeout <= 0.0 or (last_scan_time is not None and now - last_scan_time <= timeout):
        return ""
    age = "never" if last_scan_time is None else f"{now - last_scan_time:.1f} s ago"
    return f"no scan within sensor_timeout {timeout} s (last {age})"


@dataclass
class Goal:
    """A navigation goal in the map frame; ``yaw`` None = any final heading."""

    x: float
    y: float
    yaw: float | None


@dataclass
class StepResult:
    """What the node must do now: send (v, w) (m/s, rad/s); ``outcome`` is None while the goal is
    active, else ``succeeded`` or ``aborted`` with ``text``; ``new_plan`` is set when a plan
    was made this step (to publish)."""

    v: float
    w: float
    state: str
    outcome: str | None = None
    text: str = ""
    new_plan: Plan | None = None
    events: list[str] = dataclasses.field(default_factory=list)   # goal status changes this step (log once)


class Navigator:
    """Goal -> commands, with replanning and recovery; time is passed in (s)."""

    def __init__(self, params: NavigatorParams, ctrl_params: ControllerParams, planner: GlobalPlanner,
                 controller: LocalController, costmap: LayeredCostmap) -> None:
        self.p = params
        self.cp = ctrl_params
        self.planner = planner
        self.controller = controller
        self.costmap = costmap
        self.goal: Goal | None = None
        self.plan: Plan | None = None
        self.plan_from: Pose2D | None = None     # where the robot stood when self.plan was made
        self.state = "idle"
        self.status = "idle"            # human-readable goal status (the last event)
        self._events: list[str] = []
        self.hold = ""                  # why the robot must wait ('' = it may drive): set_hold
        self.trail: list[Pose2D] = []   # the poses the robot drove through, oldest first (RETREATING)
        self.retreat_request = ""       # why another module asked for a retreat (request_retreat)
        self.giving_way_until = -math.inf   # after a retreat: no planning through another robot until then
        self._plan_through_robot = False    # the latest plan goes through another robot (robots_as_cost)
        self.giving_way_reason = ""
        self.escapes = 0                    # escapes of the current goal (MAX_ESCAPES)
        self.robot_near_t = -math.inf       # the last time another robot was within SQUEEZE_NEAR (this goal)
        self._reset_timers(0.0)

    def set_hold(self, reason: str) -> None:
        """Make the robot wait (``reason``, e.g. 'waiting for zone 3, held by chefbot2') or, with '',
        let it drive on.  A held goal neither recovers nor aborts for lack of progress."""
        self.hold = reason

    def _say(self, status: str) -> None:
        """Record a goal status change (the node logs each once and publishes the latest)."""
        if status != self.status:
            self.status = status
            self._events.append(status)

    def _out(self, res: StepResult) -> StepResult:
        res.events, self._events = self._events, []
        return res

    def _reset_timers(self, t: float) -> None:
        self.last_valid_plan = t
        self.last_valid_control = t
        self.last_plan_time = -math.inf
        self.need_plan = True
        self.recovery_index = 0
        self.recovery: str | None = None
        self.recovery_state: dict[str, float] = {}
        self.osc_pose: Pose2D | None = None
        self.osc_time = t
        self.cleared_for_goal = False
        self.stale_since: float | None = None
        self.blocked_since: float | None = None

    # --- goal management -------------------------------------------------------------------------
    def set_goal(self, goal: Goal, t: float) -> None:
        """Start (or replace) a goal; the controller keeps its velocity for a smooth hand-over."""
        self.goal = goal
        self.plan = None
        self.state = "planning"
        self.status = ""
        self.giving_way_until = -math.inf
        self.escapes = 0
        self.robot_near_t = -math.inf
        self._say("planning")
        self._reset_timers(t)

    def restart(self, t: float) -> None:
        """Time jumped back: restart the current goal's timers at ``t`` (s)."""
        self.trail.clear()
        if self.goal is not None:
            self.set_goal(self.goal, t)

    def request_retreat(self, reason: str) -> None:
        """Give way: at the next step of a goal, reverse up to ``retreat_distance`` along the way the
        robot came, then plan afresh (a fleet's mutual block: this robot backs off for another)."""
        self.retreat_request = reason or "asked to give way"

    def _record(self, pose: Pose2D) -> None:
        """Add ``pose`` to the trail when it is TRAIL_SPACING from the last one (a jump restarts it);
        back near the one before, the last is dropped (the robot reversed: the way it came is shorter)."""
        if self.trail and pose.distance(self.trail[-1]) > TRAIL_JUMP:
            self.trail.clear()
        while len(self.trail) > 1 and pose.distance(self.trail[-2]) < TRAIL_SPACING:
            self.trail.pop()
        if not self.trail or pose.distance(self.trail[-1]) >= TRAIL_SPACING:
            self.trail.append(pose)
            del self.trail[:-TRAIL_MAX]

    def plan_between(self, start: tuple[float, float], goal: Goal) -> Plan:
        """A global plan from ``start`` (x, y m) to the goal on the current costmap (PlanningError if none)."""
        return self.planner.plan(self.costmap.master(), start, (goal.x, goal.y))

    def cancel(self) -> None:
        """Drop the goal; the caller sends the zero command."""
        self.goal = None
        self.plan = None
        self.state = "idle"
        self.status = "idle"
        self.controller.reset()

    # --- helpers -----------------------------------------------------------------------------------
    def _finish(self, outcome: str, text: str) -> StepResult:
        self.goal = None
        self.plan = None
        self.state = "idle"
        self.controller.reset()
        self._say(f"{outcome}: {text}")
        return StepResult(0.0, 0.0, "idle", outcome, text)

    def _blocked_by_sensors(self, err: PlanningError) -> bool:
        """The goal is in or too near an obstacle only because of what the sensors marked: on the
        map alone it is free (such a goal is retried until planner_patience, then recovered, then
        aborted; a goal the map itself blocks aborts at once)."""
        if err.kind not in ("goal_in_obstacle", "goal_too_close"):
            return False
        res = self.costmap.info.resolution
        static = self.costmap.window(self.goal.x, self.goal.y, 4 * res, 4 * res, static_only=True)
        return int(static.cost_at(self.goal.x, self.goal.y)) < INSCRIBED

    def _try_plan(self, pose: Pose2D, t: float) -> tuple[Plan | None, PlanningError | None]:
        self.last_plan_time = t
        start, goal = (pose.x, pose.y), (self.goal.x, self.goal.y)
        self._plan_through_robot = False
        try:
            return self.planner.plan(self.costmap.master(), start, goal), None
        except PlanningError as exc:
            if exc.kind not in GOAL_ERRORS or not self.costmap.robots_in_view() or t < self.giving_way_until:
                return None, exc
            err = exc
        # another robot of the fleet is in the only way (in an aisle, on the goal): plan through it and
        # wait behind it -- it drives on, or the traffic rule makes one of the two give way
        try:
            plan = self.planner.plan(self.costmap.master(robots_as_cost=True), start, goal)
        except PlanningError:
            return None, err
        self._plan_through_robot = True
        return plan, None

    def _path_blocked(self, pose: Pose2D) -> bool:
        """Is there an inscribed/lethal/unknown cell on the path ahead (new obstacle)?"""
        if self.plan is None:
            return False
        pts = self.plan.points
        d = np.hypot(pts[:, 0] - pose.x, pts[:, 1] - pose.y)
        i = int(np.argmin(d))
        ahead = pts[i:]
        seg = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(ahead, axis=0).T))))
        ahead = ahead[seg <= self.p.path_check_distance]
        # the robot's own surroundings are the controller's business (it may start inside the
        # inscribed zone); look from one robot radius ahead
        far = np.hypot(ahead[:, 0] - pose.x, ahead[:, 1] - pose.y) > self.costmap.params.robot_radius
        # a window around the robot, not the whole inflated map: this runs every control cycle and
        # the scan invalidates the global costmap at 10 Hz (60 ms to inflate 1.4 M cells)
        side = 2.0 * self.p.path_check_distance + 0.5
        cost = self.costmap.window(pose.x, pose.y, side, side).cost_at(ahead[far, 0], ahead[far, 1])
        return bool(np.any(cost >= INSCRIBED))

    def _start_recovery(self, t: float, pose: Pose2D, why: str) -> StepResult:
        if not self.p.recovery_behavior_enabled or self.recovery_index >= len(RECOVERIES):
            return self._finish("aborted", f"{why}; recovery behaviours exhausted")
        self.recovery = RECOVERIES[self.recovery_index]
        self.recovery_index += 1
        self.recovery_reason = why
        self.recovery_state = {"t0": t, "yaw": pose.yaw, "turned": 0.0, "x": pose.x, "y": pose.y}
        self.state = "recovering"
        self.controller.reset()
        self._say(f"recovering: {self.recovery.replace('_', ' ')} (because {why})")
        return self._recover(t, pose)

    def _start_retreat(self, t: float, pose: Pose2D, why: str, kind: str = "retreat") -> StepResult:
        """Reverse along the trail (the recovery 'retreat' or 'escape', outside the recovery order)."""
        self.recovery = kind
        self.recovery_reason = why
        self.recovery_state = {"t0": t, "yaw": pose.yaw, "turned": 0.0, "x": pose.x, "y": pose.y, "moved": 0.0,
                               "last_x": pose.x, "last_y": pose.y}
        self.state = "recovering"
        self.controller.reset()
        self._say(f"backing out the way it came (because {why})")
        return self._recover(t, pose)

    def _room_to_turn(self, pose: Pose2D) -> bool:
        """Is a whole turn on the spot at ``pose`` free (footprint against the local costmap; a robot
        touching something where it stands has no room)?"""
        check = getattr(self.controller, "poses_collide", None)
        if check is None or getattr(self.controller, "footprint_pts", None) is None:
            return True
        local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
        yaws = pose.yaw + np.linspace(0.0, 2.0 * math.pi, 126, endpoint=False)
        return not check(np.full(len(yaws), pose.x), np.full(len(yaws), pose.y), yaws, local)[0]

    def _retreat_command(self, t: float, pose: Pose2D, distance: float) -> tuple[float, float, bool]:
        """(v, w, done) of one retreat step of at most ``distance`` m: steer backwards to the trail pose
        RETREAT_LOOKAHEAD m back."""
        rs = self.recovery_state
        rs["moved"] += math.hypot(pose.x - rs["last_x"], pose.y - rs["last_y"])
        rs["last_x"], rs["last_y"] = pose.x, pose.y
        # steer to the first trail pose (going back) at least RETREAT_LOOKAHEAD away
        while len(self.trail) > 1 and pose.distance(self.trail[-1]) < RETREAT_LOOKAHEAD:
            self.trail.pop()
        timeout = t - rs["t0"] > 3.0 * distance / RETREAT_SPEED + 2.0
        if rs["moved"] >= distance or timeout or not self.trail or \
                pose.distance(self.trail[-1]) < 0.5 * TRAIL_SPACING:
            rs["ended"] = (f"{rs['moved']:.2f} m reversed" if rs["moved"] >= distance else
                           f"not done in {t - rs['t0']:.0f} s" if timeout else "at the end of its trail")
            return 0.0, 0.0, True
        target = self.trail[-1]
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        dx, dy = target.x - pose.x, target.y - pose.y
        lx, ly = -(c * dx + s * dy), -(-s * dx + c * dy)      # mirrored: the target as if it were ahead
        local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
        touched = getattr(self.controller, "without_touched", None)
        if self.recovery == "escape" and touched is not None:
            local = touched(local, pose)     # a robot wedged in a gap's mouth may brush what it touches
        if lx <= 0.0 or abs(math.atan2(ly, lx)) > 1.0:
            # the trail is not behind the robot.  An escape may turn back first: a robot that began to turn
            # on the spot in a dead-end aisle and was stopped part-way stands askew to the way it came (the
            # cafe's 0.50 m aisle, its camera bar ~2 cm from a table: both escapes ended at once and the
            # goal aborted); turning back sweeps only what the turn had swept
            return self._turn_back(t, pose, math.atan2(-dy, -dx), local)
        curvature = 2.0 * ly / (lx * lx + ly * ly)
        v = -RETREAT_SPEED
        w = -v * curvature
        w = min(max(w, -self.cp.max_vel_theta), self.cp.max_vel_theta)
        arc = getattr(self.controller, "arc_collides", None)
        blocked = arc(pose, v, w, local) if arc is not None else _arc_blocked(local, pose, v, RETREAT_LOOKAHEAD)
        if blocked:     # something came behind the robot (a guest, another robot): stop retreating
            rs["ended"] = f"something behind it after {rs['moved']:.2f} m"
            return 0.0, 0.0, True
        return v, w, False

    def _turn_back(self, t: float, pose: Pose2D, heading: float, local) -> tuple[float, float, bool]:
        """(v, w, done) of an escape's turn on the spot to ``heading`` (its back towards the trail), for at
        most ESCAPE_TURN_S; done at once for a retreat, or when the turn would sweep into something."""
        rs = self.recovery_state
        err = wrap_angle(heading - pose.yaw)
        check = getattr(self.controller, "rotation_collides", None)
        if self.recovery != "escape" or check is None or t - rs.setdefault("turn_t0", t) > ESCAPE_TURN_S \
                or check(pose, err, local)[0]:
            rs["ended"] = (f"its trail {abs(math.degrees(err)):.0f} deg off its back" +
                           ("" if self.recovery != "escape" or check is None else
                            f", turned for {ESCAPE_TURN_S:g} s" if t - rs["turn_t0"] > ESCAPE_TURN_S else
                            ", no room to turn back"))
            return 0.0, 0.0, True
        speed = min(self.p.rotate_speed, max(self.cp.min_in_place_vel_theta, self.cp.rotation_gain * abs(err)))
        return 0.0, math.copysign(speed, err), False

    def _recover(self, t: float, pose: Pose2D) -> StepResult:
        rs = self.recovery_state
        done = False
        v = w = 0.0
        if self.recovery == "clear_costmaps":
            self.costmap.clear_obstacles()
            done = True
        elif self.recovery == "rotate":
            rs["turned"] += abs(wrap_angle(pose.yaw - rs["yaw"]))
            rs["yaw"] = pose.yaw
            done = rs["turned"] >= 2.0 * math.pi or t - rs["t0"] > 2.0 * 2.0 * math.pi / self.p.rotate_speed + 5.0
            # the footprint swept over the next half second of turning must be free (a corner of the
            # camera bar reaches farther than the base)
            local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
            check = getattr(self.controller, "rotation_collides", None)
            if not done and check is not None and check(pose, 0.5 * self.p.rotate_speed, local)[0]:
                done = True
                self._say("recovering: rotate skipped (no room to turn on the spot)")
            w = 0.0 if done else self.p.rotate_speed
        elif self.recovery == "escape":
            # on past the first place with room to turn, so that the robot is clear of the mouth it backed
            # out of (turning there, the new path cut the mouth's corner)
            if "room_at" not in rs and self._room_to_turn(pose):
                rs["room_at"] = rs["moved"]
            v, w, done = self._retreat_command(t, pose, min(self.p.escape_distance,
                                                            rs.get("room_at", math.inf) + ESCAPE_BEYOND))
        elif self.recovery == "retreat":
            v, w, done = self._retreat_command(t, pose, self.p.retreat_distance)
            if done:    # now let the other robot through: no planning through it for a while
                self.giving_way_until = t + self.p.give_way_wait
                self.giving_way_reason = self.recovery_reason
                self.last_plan_time = -math.inf     # plan at once from here
        elif self.recovery == "back_off":
            moved = math.hypot(pose.x - rs["x"], pose.y - rs["y"])
            behind = Pose2D(pose.x, pose.y, pose.yaw)
            local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
            blocked = _arc_blocked(local, behind, -self.p.back_off_speed, self.p.back_off_distance - moved)
            arc = getattr(self.controller, "arc_collides", None)
            if not blocked and arc is not None and getattr(self.controller, "footprint_pts", None) is not None:
                blocked = arc(pose, -self.p.back_off_speed, 0.0, local)
            timeout = t - rs["t0"] > 3.0 * self.p.back_off_distance / self.p.back_off_speed + 2.0
            done = moved >= self.p.back_off_distance or blocked or timeout
            v = 0.0 if done else -self.p.back_off_speed
        if done:
            if rs.get("ended") and self.recovery in ("escape", "retreat"):   # why it stopped, for the log
                self._say(f"recovering: {self.recovery} ended ({rs['ended']})")
            self.recovery = None
            self.state = "planning"
            self.need_plan = True
            self.last_valid_plan = t
            self.last_valid_control = t
            self.osc_pose, self.osc_time = pose, t
            self._say("planning")
            return StepResult(0.0, 0.0, "planning")
        return StepResult(v, w, "recovering")

    # --- main step ---------------------------------------------------------------------------------
    def step(self, t: float, pose: Pose2D | None, why: str = "") -> StepResult:
        """Advance the state machine (see :meth:`_step`); ``events`` lists the status changes."""
        return self._out(self._step(t, pose, why))

    def _step(self, t: float, pose: Pose2D | None, why: str = "") -> StepResult:
        """Advance the state machine at time ``t`` (s) with the robot at ``pose`` (map frame).

        ``pose`` None means there is no usable pose now (``why``: stale tf, no recent scan):
        the command is zero, and the goal aborts once that has lasted ``controller_patience``.
        """
        if self.goal is None:
            self.retreat_request = ""
            return StepResult(0.0, 0.0, "idle")
        if pose is None:
            self.stale_since = t if self.stale_since is None else self.stale_since
            if t - self.stale_since > self.p.controller_patience:
                return self._finish("aborted", f"Stopped for {self.p.controller_patience:g} s: {why}")
            self._say(f"stopped: {why}")
            return StepResult(0.0, 0.0, self.state, text=why)
        self.stale_since = None
        if self.recovery != "retreat":
            self._record(pose)
        if self.retreat_request and len(self.trail) > 1:
            why, self.retreat_request = self.retreat_request, ""
            return self._start_retreat(t, pose, why)
        self.retreat_request = ""
        if self.hold and self.state in ("controlling", "recovering") and self.recovery != "retreat":
            # a plan exists: wait on it (a retreat giving way goes on: it is what the hold waits for)
            self._reset_timers(t)
            self.need_plan = False
            self.state = "controlling"
            self._say(f"waiting: {self.hold}")
            return StepResult(0.0, 0.0, self.state, text=self.hold)
        if self.state == "recovering":
            return self._recover(t, pose)
        new_plan = None
        # planner_frequency bounds every replanning, also the ones a blocked path asks for (a blocked
        # controller used to replan -- and publish a plan -- at every control cycle)
        period = 1.0 / self.p.planner_frequency if self.p.planner_frequency > 0.0 else 1.0
        due = t - self.last_plan_time >= period
        periodic = self.p.planner_frequency > 0.0 and due
        if self.plan is not None and not self.need_plan and self._path_blocked(pose):
            self.need_plan = True
        if (self.need_plan and (self.plan is None or due)) or periodic:
            plan, err = self._try_plan(pose, t)
            if plan is not None and self.plan is not None and not self.need_plan and \
                    pose.distance(self.plan_from) < self.p.replan_hysteresis and \
                    path_length(plan.points) > remaining_length(self.plan.points, pose.x, pose.y) \
                    - self.p.replan_hysteresis:
                # the robot has hardly moved (turning on the spot), the current path is clear and the
                # new one is not clearly shorter: keep it.  Round a table with two near-equal ways the
                # plan from a pose a few mm off flipped sides, and the robot turned back after half a turn
                self.last_valid_plan = t
            elif plan is not None:
                if t < self.giving_way_until and not self._plan_through_robot:
                    self.giving_way_until = -math.inf       # a way round the other robot: giving way is over
                self.plan, self.plan_from = plan, pose
                new_plan = plan
                self.need_plan = False
                self.last_valid_plan = t
                self.controller.set_path(plan.points, self.goal.yaw)
                self.state = "controlling"
            elif err.kind in GOAL_ERRORS and not self.cleared_for_goal and self.costmap.has_marks():
                # the blocking cells may be stale marks of the scan or the point cloud (a robot that
                # has driven on leaves a trail of them): forget them and retry once
                self.cleared_for_goal = True
                self.costmap.clear_obstacles()
                return self._step(t, pose)
            elif t < self.giving_way_until and self.costmap.robots_in_view():
                # giving way: another robot is the only way; wait for it to pass, no patience running
                self.last_valid_plan = self.last_valid_control = t
                self.osc_pose, self.osc_time = pose, t
                self._say(f"waiting: giving way ({self.giving_way_reason})")
                return StepResult(0.0, 0.0, "planning", text=self.giving_way_reason)
            elif err.kind in GOAL_ERRORS and not self._blocked_by_sensors(err) and not self.costmap.robots_in_view():
                return self._finish("aborted", f"Failed to plan: {err.reason}")
            elif self.plan is None or self.need_plan:
                # (also a goal that only the sensors' marks block -- a guest at the table, a chair pulled
                # out, a mark made with a late pose: not a bad goal; and any failure while another robot
                # of the fleet is about, whose marks and body move on; the current plan is kept meanwhile)
                if t - self.last_valid_plan > self.p.planner_patience:
                    return self._start_recovery(t, pose, f"no valid plan for {self.p.planner_patience:g} s "
                                                         f"({err.reason})")
                return StepResult(0.0, 0.0, "planning")
        if self.plan is None:
            return StepResult(0.0, 0.0, "planning")
        if self.need_plan and t < self.giving_way_until:
            # giving way, between two planning attempts: not a step along the old plan (towards the robot)
            self.last_valid_plan = self.last_valid_control = t
            return StepResult(0.0, 0.0, "planning", text=self.giving_way_reason)
        local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
        cmd = self.controller.compute(pose, t, local)
        if cmd.status == "arrived":
            return self._finish("succeeded", "Goal reached.")
        # blocked by the static map (a passage narrower than the robot), and where
        narrow = cmd.status == "blocked" and cmd.where is not None and self._static_obstacle_at(*cmd.where)
        at = f" at ({cmd.where[0]:.2f}, {cmd.where[1]:.2f})" if cmd.where is not None else ""
        cannot_turn = cmd.detail == BACKING_OUT or (narrow and cmd.detail == NO_ROOM_TO_TURN)
        if cannot_turn and self.escapes < MAX_ESCAPES and len(self.trail) > 1 and \
                not getattr(self.controller, "xy_reached", False):
            # the path leaves the way the robot came and it cannot turn here: drive out the way it came (the
            # controller's own backing out follows the new path, which bends away and ran it into the side)
            self.escapes += 1
            self.blocked_since = None
            return self._start_retreat(t, pose, f"no room to turn on the spot{at}", "escape")
        if cmd.status == "blocked":
            self.need_plan = True
            self.blocked_since = t if self.blocked_since is None else self.blocked_since
            if narrow and self.costmap.robot_near(pose.x, pose.y, SQUEEZE_NEAR):
                self.robot_near_t = t
            # the map blocks the path while another robot is (or just was) beside it: planned round that
            # robot, it was squeezed against a chair or wall, not sent into too narrow an aisle; back out the
            # way it came and plan afresh (the hotel's 1.0 m chair pinch, two robots head-on)
            squeezed = narrow and t - self.robot_near_t <= self.p.narrow_patience
            if squeezed and t - self.blocked_since >= SQUEEZE_WAIT and self.escapes < MAX_ESCAPES and \
                    len(self.trail) > 1:
                self.escapes += 1
                self.blocked_since = None
                return self._start_retreat(t, pose, f"squeezed against the map beside another robot{at}", "escape")
            if narrow:
                self._say(f"blocked: passage narrower than the robot{at} ({cmd.detail})")
                if not squeezed and t - self.blocked_since > self.p.narrow_patience:
                    # the map itself leaves no room: replanning, clearing or waiting cannot help
                    return self._finish("aborted", f"blocked: aisle narrower than the robot{at} "
                                                   f"for {self.p.narrow_patience:g} s")
            else:
                self._say(f"blocked: {cmd.detail}{at}")
            if t - self.last_valid_control > self.p.controller_patience:
                return self._start_recovery(t, pose, f"no safe velocity command for "
                                                     f"{self.p.controller_patience:g} s (path blocked{at})")
        else:
            self.last_valid_control = t
            self.blocked_since = None
            if cmd.status == "rotating":
                self._say("rotating to the goal heading")
            else:
                self._say(cmd.detail or "following the path")
        # oscillation: not translating although the goal is not reached (final rotation excepted)
        if self.osc_pose is None or pose.distance(self.osc_pose) >= self.p.oscillation_distance \
                or cmd.status == "rotating":
            if self.osc_pose is not None and pose.distance(self.osc_pose) >= self.p.oscillation_distance:
                self.recovery_index = 0     # real progress: the next trouble starts the recoveries anew
            self.osc_pose, self.osc_time = pose, t
        elif self.p.oscillation_timeout > 0.0 and t - self.osc_time > self.p.oscillation_timeout:
            return self._start_recovery(t, pose, f"robot oscillating: moved less than "
                                                 f"{self.p.oscillation_distance:g} m in "
                                                 f"{self.p.oscillation_timeout:g} s")
        return StepResult(cmd.v, cmd.w, "controlling", new_plan=new_plan)


    def _static_obstacle_at(self, x: float, y: float) -> bool:
        """Is there a lethal cell of the static map within one cell of (x, y) m?"""
        info = self.costmap.info
        r, c = (int(v) for v in info.world_to_cell(x, y))
        r0, r1, c0, c1 = max(r - 1, 0), min(r + 2, info.height), max(c - 1, 0), min(c + 2, info.width)
        return r0 < r1 and c0 < c1 and bool(np.any(self.costmap.static[r0:r1, c0:c1] == LETHAL))


def _arc_blocked(costmap, pose: Pose2D, v: float, dist: float) -> bool:
    """Would driving straight (v sign gives direction) for ``dist`` m enter an inscribed cell?"""
    if dist <= 0.0:
        return False
    s = np.linspace(0.02, dist + 0.05, 10) * math.copysign(1.0, v)
    xs = pose.x + s * math.cos(pose.yaw)
    ys = pose.y + s * math.sin(pose.yaw)
    return bool(np.any(costmap.cost_at(xs, ys) >= INSCRIBED))
