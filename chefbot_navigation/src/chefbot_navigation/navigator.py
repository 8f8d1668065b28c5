"""move_base's decision logic without ROS: plan, control, recover, succeed or abort (pure).

The node calls :meth:`Navigator.step` at the controller rate with the time
(s), the robot pose in the map frame, and gets a velocity command plus an
outcome when the goal is finished.  Planning, control and recovery follow
move_base's state machine:

* PLANNING: plan on the global costmap.  Goals inside an obstacle, in
  unknown space, off the map or unreachable abort at once, after one
  'clear costmaps' retry (the blocking cells may be stale scan marks).
  Other planner failures are retried until ``planner_patience``.
* CONTROLLING: the local controller follows the plan; the plan is renewed
  at ``planner_frequency`` and at once when an inscribed/lethal cell appears
  on the remaining path within ``path_check_distance``.  A controller that
  finds no safe command for ``controller_patience``, or a robot that moves
  less than ``oscillation_distance`` in ``oscillation_timeout`` (final yaw
  alignment excepted), triggers recovery.
* RECOVERING: the behaviours run in order -- clear the scan obstacles,
  rotate in place once around, back off -- each followed by a fresh plan;
  when the last one has run and the robot is still stuck the goal aborts.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_navigation.controller import ControllerParams, LocalController
from chefbot_navigation.costmap import INSCRIBED, LayeredCostmap
from chefbot_navigation.planners import GlobalPlanner, Plan, PlanningError

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
    back_off_distance: float = 0.15       # m
    back_off_speed: float = 0.08          # m/s
    rotate_speed: float = 1.0             # rad/s of the rotate recovery

    def __post_init__(self) -> None:
        if self.planner_frequency < 0.0:
            raise ValueError(f"planner_frequency must be >= 0 Hz, got {self.planner_frequency}")
        for name in ("planner_patience", "controller_patience", "oscillation_distance", "path_check_distance",
                     "local_window", "back_off_distance", "back_off_speed", "rotate_speed"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if self.oscillation_timeout < 0.0:
            raise ValueError(f"oscillation_timeout must be >= 0 s, got {self.oscillation_timeout}")


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
        self.state = "idle"
        self._reset_timers(0.0)

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

    # --- goal management -------------------------------------------------------------------------
    def set_goal(self, goal: Goal, t: float) -> None:
        """Start (or replace) a goal; the controller keeps its velocity for a smooth hand-over."""
        self.goal = goal
        self.plan = None
        self.state = "planning"
        self._reset_timers(t)

    def cancel(self) -> None:
        """Drop the goal; the caller sends the zero command."""
        self.goal = None
        self.plan = None
        self.state = "idle"
        self.controller.reset()

    # --- helpers -----------------------------------------------------------------------------------
    def _finish(self, outcome: str, text: str) -> StepResult:
        self.goal = None
        self.plan = None
        self.state = "idle"
        self.controller.reset()
        return StepResult(0.0, 0.0, "idle", outcome, text)

    def _try_plan(self, pose: Pose2D, t: float) -> tuple[Plan | None, PlanningError | None]:
        self.last_plan_time = t
        try:
            plan = self.planner.plan(self.costmap.master(), (pose.x, pose.y), (self.goal.x, self.goal.y))
        except PlanningError as exc:
            return None, exc
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
        return self._recover(t, pose)

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
            w = 0.0 if done else self.p.rotate_speed
        elif self.recovery == "back_off":
            moved = math.hypot(pose.x - rs["x"], pose.y - rs["y"])
            behind = Pose2D(pose.x, pose.y, pose.yaw)
            local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
            blocked = _arc_blocked(local, behind, -self.p.back_off_speed, self.p.back_off_distance - moved)
            timeout = t - rs["t0"] > 3.0 * self.p.back_off_distance / self.p.back_off_speed + 2.0
            done = moved >= self.p.back_off_distance or blocked or timeout
            v = 0.0 if done else -self.p.back_off_speed
        if done:
            self.recovery = None
            self.state = "planning"
            self.need_plan = True
            self.last_valid_plan = t
            self.last_valid_control = t
            self.osc_pose, self.osc_time = pose, t
            return StepResult(0.0, 0.0, "planning")
        return StepResult(v, w, "recovering")

    # --- main step ---------------------------------------------------------------------------------
    def step(self, t: float, pose: Pose2D) -> StepResult:
        """Advance the state machine at time ``t`` (s) with the robot at ``pose`` (map frame)."""
        if self.goal is None:
            return StepResult(0.0, 0.0, "idle")
        if self.state == "recovering":
            return self._recover(t, pose)
        new_plan = None
        periodic = (self.p.planner_frequency > 0.0 and t - self.last_plan_time >= 1.0 / self.p.planner_frequency)
        if self.plan is not None and not self.need_plan and self._path_blocked(pose):
            self.need_plan = True
        if self.need_plan or periodic:
            plan, err = self._try_plan(pose, t)
            if plan is not None:
                self.plan = plan
                new_plan = plan
                self.need_plan = False
                self.last_valid_plan = t
                self.controller.set_path(plan.points, self.goal.yaw)
                self.state = "controlling"
            elif err.kind in GOAL_ERRORS:
                if not self.cleared_for_goal and bool(self.costmap.obstacles.any()):
                    # the blocking cells may be stale marks from the scan: forget them and retry once
                    self.cleared_for_goal = True
                    self.costmap.clear_obstacles()
                    return self.step(t, pose)
                return self._finish("aborted", f"Failed to plan: {err.reason}")
            elif self.plan is None or self.need_plan:
                if t - self.last_valid_plan > self.p.planner_patience:
                    return self._start_recovery(t, pose, f"no valid plan for {self.p.planner_patience:g} s "
                                                         f"({err.reason})")
                return StepResult(0.0, 0.0, "planning")
        if self.plan is None:
            return StepResult(0.0, 0.0, "planning")
        local = self.costmap.window(pose.x, pose.y, self.p.local_window, self.p.local_window)
        cmd = self.controller.compute(pose, t, local)
        if cmd.status == "arrived":
            return self._finish("succeeded", "Goal reached.")
        if cmd.status == "blocked":
            self.need_plan = True
            if t - self.last_valid_control > self.p.controller_patience:
                return self._start_recovery(t, pose, f"no safe velocity command for "
                                                     f"{self.p.controller_patience:g} s (path blocked)")
        else:
            self.last_valid_control = t
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


def _arc_blocked(costmap, pose: Pose2D, v: float, dist: float) -> bool:
    """Would driving straight (v sign gives direction) for ``dist`` m enter an inscribed cell?"""
    if dist <= 0.0:
        return False
    s = np.linspace(0.02, dist + 0.05, 10) * math.copysign(1.0, v)
    xs = pose.x + s * math.cos(pose.yaw)
    ys = pose.y + s * math.sin(pose.yaw)
    return bool(np.any(costmap.cost_at(xs, ys) >= INSCRIBED))
