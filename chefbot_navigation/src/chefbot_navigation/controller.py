"""Local controllers: follow a global path with a differential-drive robot (pure).

Interface: ``LocalController`` with ``set_path``, ``reset`` and
``compute(pose, t, costmap) -> Command``.  Implementation ``regulated_pure_pursuit``:

* pure pursuit on a lookahead point (lookahead grows with speed) with the
  speed regulated down for tight curvature, for high costmap cost around
  the robot (near obstacles) and on the final approach (v <= sqrt(2 a d));
* rotates in place first when the path leaves at a large angle;
* every command is checked by forward-simulating its arc over a horizon on
  the local costmap with the robot's footprint (:meth:`set_footprint`; points
  covering the polygon, checked against lethal/unknown cells -- without one, the
  centre against inscribed cells): a colliding command is slowed down, and if
  even a crawl collides the robot stops and reports ``blocked`` with where;
* rotations in place are checked too (the footprint swept over the turn): if
  the shorter way round collides the other is tried, else ``blocked``;
* final approach: once within ``xy_goal_tolerance`` (an internal, tighter
  target is used to leave margin) it rotates in place to the goal yaw;
  if the goal is close behind the robot it backs up instead of turning round;
* acceleration limits on v and w between calls (dt from the given time),
  except for a collision stop, which may brake at ``decel_lim_x``.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from scipy import ndimage

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_navigation.costmap import INSCRIBED, LETHAL, NO_INFORMATION, Costmap

XY_RELEASE = 2.0   # x xy_goal_tolerance: a reached position is given up only this far from the goal
NO_ROOM_TO_TURN = "no room to turn on the spot"   # the detail of a command blocked by a turn (Navigator escapes)
BACKING_OUT = "backing out of a narrow passage"   # the detail of a command reversing along the new path
TOUCH_SLACK = 0.03  # m: lethal cells this close to the footprint where it stands count as touched (without_touched)
# m: a turn on the spot is judged from where it started (the robot does not move while it turns; its pose
# estimate does, by the localization's jitter) unless the estimate moves this far: a real correction
TURN_ANCHOR_RESET = 0.10


@dataclass(frozen=True)
class ControllerParams:
    """Controller tunables (m, s, rad); names as move_base's local planners' where they match."""

    max_vel_x: float = 0.35              # m/s
    max_vel_theta: float = 2.5           # [rad/s] largest turn rate commanded (> 0); a tighter curve is driven slower
    min_in_place_vel_theta: float = 0.15  # rad/s, slowest useful rotation (static friction)
    acc_lim_x: float = 0.8               # [m/s^2] rate limit of the linear command (> 0); also caps the speed so the
                                         # robot can stop at the goal
    decel_lim_x: float = 1.6             # m/s^2, only used to stop for a collision
    acc_lim_theta: float = 3.0           # [rad/s^2] rate limit of the angular command (> 0)
    decel_lim_theta: float = 2.0         # rad/s^2, turns on the spot brake at this (< acc_lim_theta: the
                                         # braking curve stays within the rate limiter's reach)
    rotation_latency: float = 0.1        # s from a pose to the wheels obeying its command (pose age, control
                                         # period, drive response): a turn brakes that much earlier
    lookahead_time: float = 1.2          # s, lookahead = v * time, clamped to the two below
    min_lookahead_dist: float = 0.3      # [m] shortest lookahead, used at low speed (> 0)
    max_lookahead_dist: float = 0.7      # [m] longest lookahead (>= min_lookahead_dist); closer than this to the
                                         # goal, the goal approach (approach_gain) starts
    rotate_to_heading_angle: float = 0.7  # rad, rotate in place when the path leaves at a larger angle
    regulated_min_radius: float = 0.6    # m, slow down on curves tighter than this radius
    approach_gain: float = 0.8           # 1/s, v <= gain * distance to goal near the goal
    min_approach_vel: float = 0.04       # [m/s] least forward speed near the goal (half of it elsewhere), so the
                                         # robot does not stall short of the goal
    rotation_gain: float = 2.5           # 1/s, w <= gain * heading error
    near_obstacle_slowdown: float = 0.6  # fraction of speed removed at cost 252 under the robot
    collision_horizon: float = 1.0       # s of forward simulation for the collision check
    reverse_dist: float = 0.25           # m, back up to goals closer than this behind the robot
    xy_goal_tolerance: float = 0.05      # m
    yaw_goal_tolerance: float = 0.05     # rad
    controller_frequency: float = 10.0   # Hz, nominal call rate (dt fallback)

    def __post_init__(self) -> None:
        for name in ("max_vel_x", "max_vel_theta", "acc_lim_x", "decel_lim_x", "acc_lim_theta",
                     "lookahead_time", "min_lookahead_dist", "xy_goal_tolerance", "yaw_goal_tolerance",
                     "controller_frequency", "collision_horizon", "rotation_gain", "approach_gain",
                     "decel_lim_theta"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not 0.0 <= self.rotation_latency < 1.0:
            raise ValueError(f"rotation_latency must be in [0, 1) s, got {self.rotation_latency}")
        if self.max_lookahead_dist < self.min_lookahead_dist:
            raise ValueError("max_lookahead_dist must be >= min_lookahead_dist")
        if not 0.0 <= self.near_obstacle_slowdown < 1.0:
            raise ValueError("near_obstacle_slowdown must be in [0, 1)")


@dataclass
class Command:
    """Velocity command (m/s, rad/s) and the controller's status: ``following``, ``rotating``
    (final yaw alignment), ``arrived`` (zero command) or ``blocked`` (zero translation);
    ``detail`` says more (``slowing for obstacle``, ``turning on the spot``, why blocked) and
    ``where`` is the (x, y) m of a blocking collision when known."""

    v: float
    w: float
    status: str
    detail: str = ""
    where: tuple[float, float] | None = None


class LocalController(Protocol):
    """What move_base needs from a local controller."""

    def set_path(self, points: np.ndarray, goal_yaw: float | None) -> None:
        """New global path (N, 2) m in the map frame; goal yaw (rad) or None to keep any heading."""
        ...

    def reset(self) -> None:
        """Forget the path and the last command (robot assumed stopped)."""
        ...

    def compute(self, pose: Pose2D, t: float, costmap: Costmap) -> Command:
        """Command for the robot at ``pose`` (map frame) at time ``t`` s."""
        ...


def arc_points(pose: Pose2D, v: float, w: float, ts: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Poses (x m, y m, yaw rad arrays) reached after times ``ts`` (s) driving (v m/s, w rad/s) from ``pose``."""
    ts = np.asarray(ts, dtype=float)
    if abs(w) < 1e-6:
        xs = pose.x + v * ts * math.cos(pose.yaw)
        ys = pose.y + v * ts * math.sin(pose.yaw)
    else:
        th = pose.yaw + w * ts
        xs = pose.x + v / w * (np.sin(th) - math.sin(pose.yaw))
        ys = pose.y - v / w * (np.cos(th) - math.cos(pose.yaw))
    return xs, ys, pose.yaw + w * ts


def _limit(value: float, prev: float, rate: float, dt: float) -> float:
    return min(max(value, prev - rate * dt), prev + rate * dt)


class RegulatedPurePursuit:
    """Regulated pure pursuit with collision checking and final yaw alignment."""

    def __init__(self, params: ControllerParams) -> None:
        self.p = params
        self.path = np.zeros((0, 2))
        self.goal_yaw: float | None = None
        self.footprint_pts: np.ndarray | None = None
        self.reset()

    def set_footprint(self, points: np.ndarray | None) -> None:
        """Points (K, 2) m covering the robot's footprint in its base frame (None: round robot, centre
        checked against inscribed cells)."""
        self.footprint_pts = None if points is None else np.asarray(points, dtype=float).reshape(-1, 2)

    def poses_collide(self, xs: np.ndarray, ys: np.ndarray, yaws: np.ndarray,
                      costmap: Costmap) -> tuple[bool, tuple[float, float] | None]:
        """Does the robot at any of the poses (m, rad) overlap a lethal/unknown cell? And the first such point."""
        xs, ys, yaws = np.atleast_1d(xs), np.atleast_1d(ys), np.atleast_1d(yaws)
        if self.footprint_pts is None:
            cost = costmap.cost_at(xs, ys)
            hit = np.nonzero(cost >= INSCRIBED)[0]
            return (True, (float(xs[hit[0]]), float(ys[hit[0]]))) if len(hit) else (False, None)
        fp = self.footprint_pts
        c, s = np.cos(yaws)[:, None], np.sin(yaws)[:, None]
        px = xs[:, None] + c * fp[None, :, 0] - s * fp[None, :, 1]
        py = ys[:, None] + s * fp[None, :, 0] + c * fp[None, :, 1]
        cost = costmap.cost_at(px, py)
        hit = np.argwhere(cost >= LETHAL)
        if len(hit) == 0:
            return False, None
        i, k = hit[0]
        return True, (float(px[i, k]), float(py[i, k]))

    def without_touched(self, costmap: Costmap, pose: Pose2D, slack: float = TOUCH_SLACK,
                        unknown: bool = False) -> Costmap:
        """``costmap`` with the lethal cells within ``slack`` m of the footprint at ``pose`` made free: what
        the robot already (nearly) touches -- a bump, a mislocalisation, a wedge in a gap's mouth -- may
        be brushed on the way out, but nothing it has not reached.  ``unknown``: unknown cells are free
        too (all of them)."""
        if self.footprint_pts is None:
            return costmap
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        fp = self.footprint_pts
        row, col = costmap.info.world_to_cell(pose.x + c * fp[:, 0] - s * fp[:, 1],
                                              pose.y + s * fp[:, 0] + c * fp[:, 1])
        near = np.zeros(costmap.cost.shape, dtype=bool)
        inside = costmap.info.inside(row, col)
        near[row[inside], col[inside]] = True
        near = ndimage.binary_dilation(near, iterations=max(int(math.ceil(slack / costmap.info.resolution)), 1))
        cost = costmap.cost.copy()
        cost[near & (cost == LETHAL)] = 0
        if unknown:
            cost[cost == NO_INFORMATION] = 0
        return Costmap(costmap.info, cost)

    def rotation_collides(self, pose: Pose2D, angle: float, costmap: Costmap) -> tuple[bool, tuple | None]:
        """Would turning on the spot by ``angle`` rad (signed) sweep the footprint into an obstacle?  A robot
        already touching something (mislocalised, bumped) may turn past what it touches, into nothing else."""
        if self.footprint_pts is None or abs(angle) < 1e-6:
            return False, None
        n = max(int(math.ceil(abs(angle) / 0.05)), 1)
        yaws = pose.yaw + np.linspace(0.0, angle, n + 1)[1:]
        here = self.poses_collide(np.array([pose.x]), np.array([pose.y]), np.array([pose.yaw]), costmap)[0]
        if here:
            # turning may free it, so do not freeze; but a robot touching one side of a narrow aisle used to
            # turn freely until its camera bar wedged it diagonally, where it could neither turn nor back out.
            # Unknown space does not stop it: exploring, a robot stands at the edge of what it has seen (the
            # camera sees nothing nearer than 0.45 m) and, touching unknown cells, could not turn at all: it
            # stood "blocked: no room to turn" until the explorer gave its goal up (20-30 s each time,
            # slam_workflow_hotel in CI), where before this rule it turned freely
            costmap = self.without_touched(costmap, pose, unknown=True)
        return self.poses_collide(np.full(n, pose.x), np.full(n, pose.y), yaws, costmap)

    def reset(self) -> None:
        """Forget the motion state (speeds, time, progress along the path)."""
        self.v = 0.0
        self.w = 0.0
        self.t: float | None = None
        self.index = 0
        self.xy_reached = False
        self.turn_at: tuple[float, float] | None = None   # where the turn on the spot under way started

    def set_path(self, points: np.ndarray, goal_yaw: float | None) -> None:
        """Follow ``points`` (N x 2, m) to a final heading ``goal_yaw`` (rad; None = any)."""
        pts = np.asarray(points, dtype=float).reshape(-1, 2)
        if len(pts) == 0:
            raise ValueError("empty path")
        same_goal = len(self.path) and np.allclose(self.path[-1], pts[-1]) and goal_yaw == self.goal_yaw
        self.path = pts
        self.goal_yaw = goal_yaw
        self.index = 0
        if not same_goal:
            self.xy_reached = False

    # --- helpers ---------------------------------------------------------------------------------
    def _dt(self, t: float) -> float:
        dt = 1.0 / self.p.controller_frequency if self.t is None else t - self.t
        # a stalled or backwards clock must not unlock a huge velocity step
        return min(max(dt, 0.0), 2.0 / self.p.controller_frequency)

    def _lookahead_point(self, pose: Pose2D, dist: float) -> np.ndarray:
        pts = self.path
        # progress: nearest point within a window ahead of the last one (paths may loop back)
        hi = min(len(pts), self.index + 200)
        d = np.hypot(pts[self.index:hi, 0] - pose.x, pts[self.index:hi, 1] - pose.y)
        self.index += int(np.argmin(d))
        rest = pts[self.index:]
        dr = np.hypot(rest[:, 0] - pose.x, rest[:, 1] - pose.y)
        beyond = np.nonzero(dr >= dist)[0]
        return rest[beyond[0]] if len(beyond) else rest[-1]

    def arc_collides(self, pose: Pose2D, v: float, w: float, costmap: Costmap) -> bool:
        """Does the arc of (v, w) over the horizon (plus stopping) hit an obstacle (footprint vs lethal
        cells, or without a footprint the centre vs cells of cost >= 253)?  The point is kept in
        ``self.last_hit``."""
        self.last_hit = None
        if abs(v) < 1e-6:
            return False   # turning on the spot is checked by rotation_collides
        horizon = self.p.collision_horizon + abs(v) / self.p.decel_lim_x
        n = max(int(math.ceil(abs(v) * horizon / (0.5 * costmap.info.resolution))), 2)
        xs, ys, yaws = arc_points(pose, v, w, np.linspace(0.0, horizon, n + 1)[1:])
        if self.footprint_pts is not None:
            touching, _ = self.poses_collide(np.array([pose.x]), np.array([pose.y]), np.array([pose.yaw]), costmap)
            if touching:
                # already touching (a bump, mislocalisation): allow moves that end free
                hit, where = self.poses_collide(xs[-1:], ys[-1:], yaws[-1:], costmap)
            else:
                hit, where = self.poses_collide(xs, ys, yaws, costmap)
            self.last_hit = where
            return hit
        cost = costmap.cost_at(xs, ys)
        here = int(costmap.cost_at(pose.x, pose.y))
        if here >= INSCRIBED:
            # already inside the inscribed zone (e.g. after a bump): allow moves that leave it,
            # i.e. whose cells never get worse than lethal and end up below the inscribed cost
            return bool(np.any(cost > INSCRIBED) or cost[-1] >= INSCRIBED)
        return bool(np.any(cost >= INSCRIBED))

    def _emit(self, v: float, w: float, t: float, dt: float, status: str, detail: str = "",
              emergency: bool = False, where: tuple[float, float] | None = None) -> Command:
        p = self.p
        v = min(max(v, -p.max_vel_x), p.max_vel_x)
        w = min(max(w, -p.max_vel_theta), p.max_vel_theta)
        rate = p.decel_lim_x if emergency else p.acc_lim_x
        v = _limit(v, self.v, rate, dt)
        w = _limit(w, self.w, p.acc_lim_theta, dt)
        self.v, self.w, self.t = v, w, t
        if abs(v) > 1e-6 or abs(w) < 1e-6:
            self.turn_at = None          # driving, or stopped: the next turn on the spot starts afresh
        return Command(v, w, status, detail, where)

    def _rotate_to(self, err: float, t: float, dt: float, status: str, pose: Pose2D | None = None,
                   costmap: Costmap | None = None) -> Command:
        p = self.p
        if pose is not None and costmap is not None:
            # judged where the turn started: turning on the spot, the robot stays there while its estimate
            # wanders by the localization's jitter (1-3 cm); judged from the estimate, a turn in the cafe's
            # 0.50 m aisle that started free was "blocked" part-way, the robot stood askew, could neither
            # turn on nor back out, and both escapes ended at once (cafe_aisles in CI; reproduced on the
            # unicycle with a jittered pose)
            if self.turn_at is None or math.hypot(pose.x - self.turn_at[0], pose.y - self.turn_at[1]) > \
                    TURN_ANCHOR_RESET:
                self.turn_at = (pose.x, pose.y)
            at = Pose2D(self.turn_at[0], self.turn_at[1], pose.yaw)
            hit, where = self.rotation_collides(at, err, costmap)
            if hit:
                other = err - math.copysign(2.0 * math.pi, err)      # the long way round
                hit2, _ = self.rotation_collides(at, other, costmap)
                if hit2:
                    return self._emit(0.0, 0.0, t, dt, "blocked", NO_ROOM_TO_TURN, where=where,
                                      emergency=True)
                err = other
        # the fastest turn rate from which the robot still stops at the target heading: it keeps
        # turning for rotation_latency L (the command has not taken effect yet) and then brakes at
        # decel_lim_theta a:  w L + w^2 / 2a = |err|  =>  w = sqrt((a L)^2 + 2 a |err|) - a L.
        # Near the target this is |err| / L, far from it sqrt(2 a |err|) - a L.  The old law
        # min(2 |err|, sqrt(2 acc_lim_theta |err|)) ignored the delay and braked at the full
        # acceleration limit, so a 150 deg turn ended 4-5 deg past the goal, and its gain of 2/s made
        # the last 0.5 rad of every turn creep.
        a, lat = p.decel_lim_theta, p.rotation_latency
        mag = min(p.max_vel_theta, p.rotation_gain * abs(err), math.sqrt((a * lat) ** 2 + 2.0 * a * abs(err)) - a * lat)
        mag = max(mag, p.min_in_place_vel_theta)
        return self._emit(0.0, math.copysign(mag, err), t, dt, status,
                          "turning on the spot" if status == "following" else "")

    def _goal_sideways(self, pose: Pose2D) -> bool:
        gx, gy = self.path[-1]
        bearing = wrap_angle(math.atan2(gy - pose.y, gx - pose.x) - pose.yaw)
        off_axis = min(abs(bearing), math.pi - abs(bearing))   # forwards or backwards
        return off_axis > self.p.rotate_to_heading_angle

    # --- main ----------------------------------------------------------------------------------
    def compute(self, pose: Pose2D, t: float, costmap: Costmap) -> Command:
        """Velocity command and status for the robot at ``pose`` at time ``t`` (s)."""
        p = self.p
        dt = self._dt(t)
        if len(self.path) == 0:
            return self._emit(0.0, 0.0, t, dt, "arrived", "no path")
        gx, gy = self.path[-1]
        dist_goal = math.hypot(gx - pose.x, gy - pose.y)
        # latch xy like move_base's latch_xy_goal_tolerance, but release it if we drift off -- by
        # XY_RELEASE x the tolerance: a turn on the spot does not move the robot, but the estimate
        # it is judged on wanders a few cm while the scene turns (amcl on a narrow camera); released
        # at the tolerance itself, the robot at home turned to drive 1 cm back, turned again, and
        # spun for 15 s until localization was lost (make demo at 1.5x, 2026-11-23)
        release = (XY_RELEASE if self.xy_reached else 1.0) * p.xy_goal_tolerance
        if dist_goal <= 0.5 * p.xy_goal_tolerance:
            self.xy_reached = True
        elif dist_goal <= p.xy_goal_tolerance and self._goal_sideways(pose):
            # inside the tolerance with the goal beside the robot: creeping closer would need a
            # turn on the spot and a wiggle, so accept the position as it is
            self.xy_reached = True
        elif dist_goal > release:
            self.xy_reached = False
        if self.xy_reached:
            if self.goal_yaw is None:
                return self._emit(0.0, 0.0, t, dt, "arrived")
            err = wrap_angle(self.goal_yaw - pose.yaw)
            # stop short of the tolerance: the robot keeps turning a little after the zero command
            if abs(err) <= 0.5 * p.yaw_goal_tolerance:
                return self._emit(0.0, 0.0, t, dt, "arrived")
            return self._rotate_to(err, t, dt, "rotating", pose, costmap)

        lookahead = min(max(abs(self.v) * p.lookahead_time, p.min_lookahead_dist), p.max_lookahead_dist)
        target = self._lookahead_point(pose, lookahead)
        dx, dy = target[0] - pose.x, target[1] - pose.y
        c, s = math.cos(pose.yaw), math.sin(pose.yaw)
        lx, ly = c * dx + s * dy, -s * dx + c * dy          # target in the robot frame
        near_goal = dist_goal < p.max_lookahead_dist and np.allclose(target, self.path[-1])
        reverse = near_goal and dist_goal < p.reverse_dist and lx < 0.0
        if reverse:
            lx, ly = -lx, -ly        # pursue the mirrored point, then drive backwards
        alpha = math.atan2(ly, lx)
        if abs(alpha) > p.rotate_to_heading_angle:
            if self.v < -1e-3 and abs(alpha) > 0.5 * math.pi:
                # backing out already: go on while that works (stopping to turn every other cycle halved
                # the speed, and the robot never turned anyway)
                back = self._back_out(pose, -lx, -ly, t, dt, costmap)
                if back is not None:
                    return back
            # rotating in place first keeps the robot on the path instead of swinging wide
            if abs(self.v) > 1e-3:
                return self._emit(0.0, self.w, t, dt, "following", "stopping to turn")
            if alpha * self.w < 0.0 and abs(alpha) > math.pi - 0.3:
                # the target about straight behind: keep turning the way the robot turns (the sign of the
                # bearing flipped with every step, and the robot wagged on the spot for ever)
                alpha -= math.copysign(2.0 * math.pi, alpha)
            cmd = self._rotate_to(alpha, t, dt, "following", pose, costmap)
            if cmd.status == "blocked" and abs(alpha) > 0.5 * math.pi:
                # no room to turn round (a dead-end aisle): back out along the path instead
                back = self._back_out(pose, -lx, -ly, t, dt, costmap)
                if back is not None:
                    return back
            return cmd
        l2 = lx * lx + ly * ly
        curvature = 2.0 * ly / l2 if l2 > 1e-9 else 0.0
        v = p.max_vel_x
        if abs(curvature) > 1e-9 and 1.0 / abs(curvature) < p.regulated_min_radius:
            v *= (1.0 / abs(curvature)) / p.regulated_min_radius
        here = float(costmap.cost_at(pose.x, pose.y, outside=0))
        slow = p.near_obstacle_slowdown * min(here, 252.0) / 252.0
        v *= 1.0 - slow
        if near_goal:
            v = min(v, max(p.approach_gain * dist_goal, p.min_approach_vel),
                    math.sqrt(2.0 * p.acc_lim_x * dist_goal))
        # turning-in-place part of the heading error limits v smoothly (no jerk at the threshold)
        v *= max(0.0, math.cos(alpha))
        v = max(v, p.min_approach_vel if near_goal else 0.5 * p.min_approach_vel)
        if reverse:
            v, curvature = -v, -curvature
        w = v * curvature
        if abs(w) > p.max_vel_theta:
            v *= p.max_vel_theta / abs(w)
            w = math.copysign(p.max_vel_theta, w)
        # collision check of the command after the acceleration limits would apply
        where = None
        for scale in (1.0, 0.5, 0.25):
            vv = _limit(v * scale, self.v, p.acc_lim_x, dt)
            ww = _limit(w * scale, self.w, p.acc_lim_theta, dt)
            if not self.arc_collides(pose, vv, ww, costmap):
                detail = "slowing for obstacle" if scale < 1.0 else ""
                return self._emit(v * scale, w * scale, t, dt, "following", detail)
            where = where or self.last_hit
        if not reverse:
            # narrow passage (pure pursuit cuts the corner into an aisle): follow the path itself --
            # turn on the spot towards a point just ahead, then creep along it
            cmd = self._squeeze(pose, t, dt, costmap)
            if cmd is not None:
                return cmd
        return self._emit(0.0, 0.0, t, dt, "blocked", "obstacle ahead on the path", emergency=True, where=where)

    def _back_out(self, pose: Pose2D, lx: float, ly: float, t: float, dt: float,
                  costmap: Costmap) -> Command | None:
        """Reverse slowly towards the mirrored lookahead point (``lx``, ``ly`` m in the robot frame, i.e.
        the real target is behind), or None if that collides or the target is not roughly behind."""
        p = self.p
        alpha = math.atan2(ly, lx)
        if abs(alpha) > 0.6:
            return None
        l2 = lx * lx + ly * ly
        curvature = 2.0 * ly / l2 if l2 > 1e-9 else 0.0
        v = -min(0.1, p.max_vel_x)
        w = min(max(-v * curvature, -p.max_vel_theta), p.max_vel_theta)
        if self.arc_collides(pose, _limit(v, self.v, p.acc_lim_x, dt), _limit(w, self.w, p.acc_lim_theta, dt),
                             costmap):
            return None
        return self._emit(v, w, t, dt, "following", BACKING_OUT)

    def _squeeze(self, pose: Pose2D, t: float, dt: float, costmap: Costmap) -> Command | None:
        """A slow command that tracks the path closely (lookahead 0.12 m), or None if that collides too."""
        p = self.p
        target = self._lookahead_point(pose, 0.12)
        alpha = wrap_angle(math.atan2(target[1] - pose.y, target[0] - pose.x) - pose.yaw)
        if abs(alpha) > 0.2:
            if abs(self.v) > 1e-3:
                return self._emit(0.0, self.w, t, dt, "following", "stopping to turn", emergency=True)
            cmd = self._rotate_to(alpha, t, dt, "following", pose, costmap)
            return cmd if cmd.status != "blocked" else None
        d = math.hypot(target[0] - pose.x, target[1] - pose.y)
        v = min(0.1, p.max_vel_x)
        w = min(max(2.0 * v * math.sin(alpha) / max(d, 1e-3), -p.max_vel_theta), p.max_vel_theta)
        if self.arc_collides(pose, _limit(v, self.v, p.acc_lim_x, dt), _limit(w, self.w, p.acc_lim_theta, dt),
                             costmap):
            return None
        return self._emit(v, w, t, dt, "following", "squeezing through a narrow passage")


CONTROLLERS = {"regulated_pure_pursuit": RegulatedPurePursuit}


def make_controller(name: str, params: ControllerParams) -> LocalController:
    """Controller implementation by name (``regulated_pure_pursuit``)."""
    try:
        return CONTROLLERS[name](params)
    except KeyError:
        raise ValueError(f"unknown controller {name!r}; choose one of {', '.join(sorted(CONTROLLERS))}") from None
