"""Two robots head-on at a pinch: the robots layer, the give-way retreat and the block detector together.

Each robot is a Navigator (chefbot_navigation) on a kinematic unicycle, with a robots layer fed the
other robot's state (as /fleet/robots would), and the BlockDetector watching both (as the traffic
node does).  The traffic rule is left out, as where it does not apply: a two-lane aisle pinched by a
chair (the hotel's 1.06 m pinches, where move_base cannot pass a robot), two robots already inside
one zone.  At the 0.55 m pinch each robot can only plan through the other and waits behind it;
without a tie-breaker both wait until their patience runs out.  With it, the later robot backs off
along the way it came, waits, and both arrive.  Likewise a robot parked (no goal) on another's goal:
the detector sends it to the spot room_spot picks, as the traffic node does, and the other arrives.
"""
from __future__ import annotations

import math

import numpy as np

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_fleet.blocks import BlockConfig, BlockDetector, RobotView, room_spot
from chefbot_fleet.zones import extract_zones
from chefbot_navigation.controller import ControllerParams, make_controller
from chefbot_navigation.costmap import CostmapParams, LayeredCostmap
from chefbot_navigation.navigator import Goal, Navigator, NavigatorParams
from chefbot_navigation.planners import PlannerParams, make_planner
from chefbot_navigation.robots_layer import OtherRobot, RobotsLayer, RobotsLayerParams

DT = 0.1
RADIUS = 0.2


def corridor_with_a_pinch() -> OccupancyMap:
    """A 1.6 m wide, 9 m long corridor (x -4.5..4.5) pinched to 0.55 m for 0.4 m at x = 0 (two chairs)."""
    res = 0.05
    info = GridInfo(res, 200, 60, -5.0, -1.5, 0.0)          # 10 m x 3 m
    data = np.full((60, 200), 100, dtype=np.int8)
    data[int(0.7 / res):int(2.3 / res), int(0.5 / res):int(9.5 / res)] = 0       # y -0.8..0.8, x -4.5..4.5
    data[int(0.7 / res):int(1.225 / res), int(4.8 / res):int(5.2 / res)] = 100   # pinch: y -0.8..-0.275
    data[int(1.775 / res):int(2.3 / res), int(4.8 / res):int(5.2 / res)] = 100  # and y 0.275..0.8
    return OccupancyMap(info, data)


class Robot:
    """One robot: its navigator, its costmap with a robots layer, its pose."""

    def __init__(self, name: str, occ: OccupancyMap, pose: Pose2D) -> None:
        self.name, self.pose = name, pose
        self.layers = LayeredCostmap(occ, CostmapParams(robot_radius=RADIUS, inflation_radius=0.45))
        self.layers.robots_layer = RobotsLayer(occ.info, RobotsLayerParams(), own_name=name)
        cp = ControllerParams()
        self.nav = Navigator(NavigatorParams(), cp, make_planner("dijkstra", PlannerParams(), RADIUS),
                             make_controller("regulated_pure_pursuit", cp), self.layers)
        self.v = self.w = 0.0
        self.outcome: str | None = None
        self.text = ""

    def state(self, t: float) -> OtherRobot:
        """What its fleet_member would publish."""
        path = self.nav.plan.points if (self.nav.plan is not None and self.nav.goal is not None) else np.zeros((0, 2))
        return OtherRobot(self.name, t, self.pose.x, self.pose.y, self.pose.yaw, self.v, self.w,
                          radius=RADIUS, path=path)

    def step(self, t: float) -> None:
        if self.outcome is not None:
            self.v = self.w = 0.0
            return
        res = self.nav.step(t, self.pose)
        if res.outcome:
            self.outcome, self.text = res.outcome, res.text
        self.v, self.w = res.v, res.w
        p, th = self.pose, self.pose.yaw + res.w * DT
        if abs(res.w) < 1e-9:
            self.pose = Pose2D(p.x + res.v * DT * math.cos(p.yaw), p.y + res.v * DT * math.sin(p.yaw), p.yaw)
        else:
            r = res.v / res.w
            self.pose = Pose2D(p.x + r * (math.sin(th) - math.sin(p.yaw)), p.y - r * (math.cos(th) - math.cos(p.yaw)),
                               wrap_angle(th))


def run_head_on(detector: BlockDetector | None, t_max: float = 150.0):
    occ = corridor_with_a_pinch()
    a = Robot("chefbot1", occ, Pose2D(-3.5, 0.0, 0.0))
    b = Robot("chefbot2", occ, Pose2D(3.5, 0.0, math.pi))
    a.nav.set_goal(Goal(4.0, 0.0, None), 0.0)
    b.nav.set_goal(Goal(-4.0, 0.0, None), 0.0)
    t, closest, blocks = 0.0, math.inf, []
    while t < t_max and (a.outcome is None or b.outcome is None):
        for me, other in ((a, b), (b, a)):
            me.layers.robots_layer.update(other.state(t))
            me.layers.robots_layer.refresh(t)
            me.layers.layers_changed()
        if detector is not None:
            views = [RobotView(r.name, r.pose.x, r.pose.y, RADIUS, r.state(t).path, held=False) for r in (a, b)]
            for block in detector.update(t, views):
                blocks.append(block)
                {"chefbot1": a, "chefbot2": b}[block.yielder].nav.request_retreat(block.text())
        a.step(t)
        b.step(t)
        closest = min(closest, a.pose.distance(b.pose))
        t += DT
    return a, b, t, closest, blocks


def test_head_on_at_a_pinch_one_robot_gives_way_and_both_arrive() -> None:
    a, b, t, closest, blocks = run_head_on(BlockDetector(BlockConfig(robot_radius=RADIUS)))
    assert (a.outcome, b.outcome) == ("succeeded", "succeeded"), (a.text, b.text)
    assert t < 90.0                                   # about 43 s: a 5 s standoff, 0.8 m back, the wait
    assert blocks and blocks[0].yielder == "chefbot2"
    assert closest >= 2 * RADIUS, f"the robots touched ({closest:.3f} m between centres)"
    assert math.hypot(a.pose.x - 4.0, a.pose.y) <= 0.05 and math.hypot(b.pose.x + 4.0, b.pose.y) <= 0.05


def test_without_the_detector_the_two_robots_do_not_both_arrive() -> None:
    """The case is real: with nobody giving way, the standoff ends only in an abort or the time limit."""
    a, b, _, closest, _ = run_head_on(None, t_max=90.0)
    assert (a.outcome, b.outcome) != ("succeeded", "succeeded")
    assert closest >= 2 * RADIUS


def run_parked(detector: BlockDetector | None, t_max: float = 90.0):
    """chefbot1 drives to (2.5, 0); chefbot2 stands there without a goal."""
    occ = corridor_with_a_pinch()
    zmap = extract_zones(occ)
    a = Robot("chefbot1", occ, Pose2D(-3.5, 0.0, 0.0))
    b = Robot("chefbot2", occ, Pose2D(2.5, 0.0, 0.0))
    a.nav.set_goal(Goal(2.5, 0.0, None), 0.0)
    b.outcome = "idle"
    t, closest, spots = 0.0, math.inf, []
    cfg = BlockConfig(robot_radius=RADIUS)
    while t < t_max and a.outcome is None:
        for me, other in ((a, b), (b, a)):
            me.layers.robots_layer.update(other.state(t))
            me.layers.robots_layer.refresh(t)
            me.layers.layers_changed()
        views = [RobotView(r.name, r.pose.x, r.pose.y, RADIUS, r.state(t).path) for r in (a, b)]
        for block in detector.update(t, views) if detector is not None else []:
            assert block.idle and block.yielder == "chefbot2"
            spot = room_spot(zmap.clearance, occ.info, zmap.keep_out(RADIUS), views[1], views[:1], cfg)
            spots.append(spot)
            b.nav.set_goal(Goal(spot[0], spot[1], None), t)
            b.outcome = None
        a.step(t)
        b.step(t)
        closest = min(closest, a.pose.distance(b.pose))
        t += DT
    return a, b, closest, spots


def test_a_robot_parked_on_the_goal_makes_room_and_the_other_arrives() -> None:
    a, b, closest, spots = run_parked(BlockDetector(BlockConfig(robot_radius=RADIUS)))
    assert a.outcome == "succeeded", a.text
    assert len(spots) == 1
    sx, sy = spots[0]
    assert math.hypot(sx - 2.5, sy) >= 2 * RADIUS + 0.2 - 0.05          # off the goal by two radii + margins
    assert math.hypot(b.pose.x - sx, b.pose.y - sy) <= 0.1              # and it drove there
    assert closest >= 2 * RADIUS, f"the robots touched ({closest:.3f} m between centres)"


def test_without_making_room_the_robot_does_not_arrive() -> None:
    a, _, closest, _ = run_parked(None)
    assert a.outcome != "succeeded"
    assert closest >= 2 * RADIUS
