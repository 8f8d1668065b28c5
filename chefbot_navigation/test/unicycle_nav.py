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

    def __init__(self, occ: OccupancyMap, urdf: str, start: Pose2D) -> None:
        ctrl, cost = shipped_params()
        self.ctrl = ctrl
        self.fp = footprint_from_urdf(urdf, padding=cost.footprint_padding)
        self.body = footprint_from_urdf(urdf).samples(0.01)     # the real collision bodies, unpadded
        self.layers, self.nav = build_navigator(occ, NodeParams(), NavigatorParams(), ctrl, cost, PlannerParams(),
                                                None, 0.0, self.fp)
        self.occ, self.pose, self.t = occ, start, 0.0

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
        t0, touches, events, plans, first = self.t, 0, [], [], None
        self.timeline: list[tuple[float, str]] = []
        while self.t - t0 < t_max:
            res = self.nav.step(self.t, self.pose)
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
