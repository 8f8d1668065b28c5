"""Test-only helper: move_base's Navigator driving a perfect unicycle on a map (no ROS), with the
URDF footprint, counting contacts of the real (unpadded) collision bodies with the static map.
Used by test/unit/test_aisles.py and bench/bench_aisles.py."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import yaml

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.controller import ControllerParams
from chefbot_navigation.costmap import LETHAL, CostmapParams
from chefbot_navigation.footprint import footprint_from_urdf
from chefbot_navigation.navigator import Goal, NavigatorParams, NodeParams, build_navigator
from chefbot_navigation.planners import PlannerParams

PKG = Path(__file__).resolve().parents[1]
DT = 0.1   # s, control period


def shipped_params() -> tuple[ControllerParams, CostmapParams]:
    y = yaml.safe_load((PKG / "param" / "move_base.yaml").read_text())
    ctrl = ControllerParams(**y["controller"], xy_goal_tolerance=y["xy_goal_tolerance"],
                            yaw_goal_tolerance=y["yaw_goal_tolerance"])
    return ctrl, CostmapParams(**y["costmap"])


class Run:
    """A navigator on a map driving a perfect unicycle; counts footprint contacts with the static map."""

    def __init__(self, occ: OccupancyMap, urdf: str, start: Pose2D,
                 jitter: tuple[float, float, int] | None = None) -> None:
        """``jitter`` (m, rad, seed): the navigator sees the pose through a localization error that wanders
        (a random walk decaying by 0.98 a step, about these standard deviations, from zero at the start of
        each leg), as amcl's estimate does; the robot moves, and touches, by its true pose."""
        self.jitter = jitter
        self.error = np.zeros(3)
        self.rng = np.random.default_rng(jitter[2]) if jitter else None
        ctrl, cost = shipped_params()
        self.ctrl = ctrl
        self.fp = footprint_from_urdf(urdf, padding=cost.footprint_padding)
        self.body = footprint_from_urdf(urdf).samples(0.01)     # the real collision bodies, unpadded
        self.layers, self.nav = build_navigator(occ, NodeParams(), NavigatorParams(), ctrl, cost, PlannerParams(),
                                                None, 0.0, self.fp)
        self.occ, self.pose, self.t = occ, start, 0.0

    def seen(self) -> Pose2D:
        """The pose the navigator is given: the true one, or with the wandering error of ``jitter``."""
        if self.rng is None:
            return self.pose
        sxy, syaw, _ = self.jitter
        # per 0.1 s step: the error's memory is about 5 s; 0.2 ~ sqrt(1 - 0.98^2) keeps it about (sxy, syaw)
        self.error = 0.98 * self.error + self.rng.normal(0.0, [0.2 * sxy, 0.2 * sxy, 0.2 * syaw])
        return Pose2D(self.pose.x + self.error[0], self.pose.y + self.error[1],
                      wrap_angle(self.pose.yaw + self.error[2]))

    def touching(self) -> bool:
        c, s = math.cos(self.pose.yaw), math.sin(self.pose.yaw)
        px = self.pose.x + c * self.body[:, 0] - s * self.body[:, 1]
        py = self.pose.y + s * self.body[:, 0] + c * self.body[:, 1]
        row, col = self.occ.info.world_to_cell(px, py)
        return bool(np.any(self.layers.static[row, col] == LETHAL))

    def go(self, goal: Goal, t_max: float = 300.0):
        """Drive to ``goal``: (last StepResult, seconds, contact steps, status events, plan times, first plan);
        ``self.timeline`` holds (s since the goal, event)."""
        self.nav.set_goal(goal, self.t)
        self.error = np.zeros(3)
        t0, touches, events, plans, first = self.t, 0, [], [], None
        self.timeline: list[tuple[float, str]] = []
        while self.t - t0 < t_max:
            res = self.nav.step(self.t, self.seen())
            events += res.events
            self.timeline += [(self.t - t0, e) for e in res.events]
            if res.new_plan is not None:
                plans.append(self.t)
                first = first or res.new_plan
            if res.outcome:
                return res, self.t - t0, touches, events, plans, first
            v, w, p = res.v, res.w, self.pose
            if abs(w) < 1e-9:
                self.pose = Pose2D(p.x + v * DT * math.cos(p.yaw), p.y + v * DT * math.sin(p.yaw), p.yaw)
            else:
                th = p.yaw + w * DT
                self.pose = Pose2D(p.x + v / w * (math.sin(th) - math.sin(p.yaw)),
                                   p.y - v / w * (math.cos(th) - math.cos(p.yaw)), wrap_angle(th))
            touches += self.touching()
            self.t += DT
        raise AssertionError(f"no outcome within {t_max} s; last events {events[-5:]}")



def slot_map(width: float, res: float = 0.025) -> OccupancyMap:
    """6 x 3 m room, a 1 m thick block across it at x 2.5..3.5 with a passage of ``width`` m at y 1.5."""
    n_w, n_h = int(6 / res), int(3 / res)
    data = np.zeros((n_h, n_w), np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    x0, x1 = int(2.5 / res), int(3.5 / res)
    data[:, x0:x1] = 100
    data[int(round((1.5 - width / 2) / res)):int(round((1.5 + width / 2) / res)), x0:x1] = 0
    return OccupancyMap(GridInfo(res, n_w, n_h, 0.0, 0.0, 0.0), data)


def dead_end_map(aisle: float, gap: float, angle: float, depth: float, res: float = 0.025) -> OccupancyMap:
    """8 x 8 m room (centre at 0, 0) split by a block 0.5 m + ``depth`` thick, its faces through the centre
    at ``angle`` rad; a passage crosses it along that direction: ``aisle`` m wide for ``depth`` m, then a
    ``gap`` m narrower than the robot, so the far side is unreachable for it."""
    n = int(round(8.0 / res))
    data = np.zeros((n, n), np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    ys, xs = np.mgrid[0:n, 0:n]
    x, y = (xs + 0.5) * res - 4.0, (ys + 0.5) * res - 4.0
    u = math.cos(angle) * x + math.sin(angle) * y       # along the passage
    v = -math.sin(angle) * x + math.cos(angle) * y      # across it
    block = (u > 0.0) & (u < depth + 0.5)
    hole = ((u < depth) & (np.abs(v) < aisle / 2)) | ((u >= depth) & (np.abs(v) < gap / 2))
    data[block & ~hole] = 100
    return OccupancyMap(GridInfo(res, n, n, -4.0, -4.0, 0.0), data)


def random_dead_end(rng: np.random.Generator) -> tuple[tuple[float, float, float, float], Pose2D,
                                                         tuple[float, float], tuple[float, float]]:
    """A generated :func:`dead_end_map` case: (aisle 0.40-0.52 m, gap 0.34-0.37 m, angle +-1 rad, depth
    0.4-1.2 m), a start in the room on the passage's side, a goal beyond the gap (refused, or reached
    if the robot squeezes through) and a next goal back in the room."""
    aisle, gap = rng.uniform(0.40, 0.52), rng.uniform(0.34, 0.37)
    angle, depth = rng.uniform(-1.0, 1.0), rng.uniform(0.4, 1.2)
    c, s = math.cos(angle), math.sin(angle)

    def in_room() -> tuple[float, float]:
        while True:     # 0.6 m before the block's face and 0.5 m inside the walls
            x, y = rng.uniform(-3.5, 3.5, 2)
            if c * x + s * y < -0.6:
                return float(x), float(y)

    sx, sy = in_room()
    return (aisle, gap, angle, depth), Pose2D(sx, sy, rng.uniform(-math.pi, math.pi)), \
        (3.5 * c, 3.5 * s), in_room()
