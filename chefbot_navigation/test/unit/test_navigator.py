"""move_base decision logic on a kinematic unicycle (pure Python)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.controller import ControllerParams, make_controller
from chefbot_navigation.costmap import CostmapParams, LayeredCostmap
from chefbot_navigation.navigator import Goal, Navigator, NavigatorParams
from chefbot_navigation.planners import PlannerParams, make_planner
from chefbot_navigation.robots_layer import OtherRobot, RobotsLayer, RobotsLayerParams

DT = 0.1


def room() -> OccupancyMap:
    n = 200    # 10 m x 10 m, origin (-5, -5)
    data = np.zeros((n, n), dtype=np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    data[60:140, 98:102] = 100          # a wall x in [-0.1, 0.1], y in [-2, 2]
    data[150:170, 150:170] = -1         # unknown patch around (3, 3)
    return OccupancyMap(GridInfo(0.05, n, n, -5.0, -5.0, 0.0), data)


def make_nav(**kw) -> tuple[Navigator, LayeredCostmap]:
    layers = LayeredCostmap(room(), CostmapParams())
    cp = ControllerParams()
    nav = Navigator(NavigatorParams(**kw), cp, make_planner("dijkstra", PlannerParams()),
                    make_controller("regulated_pure_pursuit", cp), layers)
    return nav, layers


def run(nav: Navigator, pose: Pose2D, t_max: float = 120.0, hook=None):
    t = 0.0
    res = None
    while t < t_max:
        if hook:
            hook(t, pose)
        res = nav.step(t, pose)
        if res.outcome:
            return res, pose, t
        v, w = res.v, res.w
        th = pose.yaw + w * DT
        if abs(w) < 1e-9:
            pose = Pose2D(pose.x + v * DT * math.cos(pose.yaw), pose.y + v * DT * math.sin(pose.yaw), pose.yaw)
        else:
            pose = Pose2D(pose.x + v / w * (math.sin(th) - math.sin(pose.yaw)),
                          pose.y - v / w * (math.cos(th) - math.cos(pose.yaw)), wrap_angle(th))
        t += DT
    return res, pose, t


def test_reaches_goal_around_wall() -> None:
    nav, _ = make_nav()
    nav.set_goal(Goal(2.0, 0.0, math.pi / 2), 0.0)
    res, pose, t = run(nav, Pose2D(-2.0, 0.0, 0.0))
    assert res.outcome == "succeeded", res.text
    assert math.hypot(pose.x - 2.0, pose.y) <= 0.05
    assert abs(wrap_angle(pose.yaw - math.pi / 2)) <= 0.05


def test_goal_in_obstacle_aborts_at_once() -> None:
    nav, _ = make_nav()
    nav.set_goal(Goal(0.0, 0.0, 0.0), 0.0)
    res, _, t = run(nav, Pose2D(-2.0, 0.0, 0.0))
    assert res.outcome == "aborted" and "inside an obstacle" in res.text and t < 1.0


def test_goal_blocked_only_by_sensor_marks_is_retried_not_refused() -> None:
    """A guest standing at the table (marked by the sensors, free on the map): the goal is not a bad
    goal -- no abort at once; when the guest leaves in time the robot delivers, when they stay the goal
    ends after patience and recoveries with the reason, not at the first plan."""
    guest = np.meshgrid(np.linspace(-2.1, -1.9, 5), np.linspace(3.4, 3.6, 5))

    def stays(until: float):
        def hook(t: float, pose: Pose2D) -> None:
            if t < until:
                layers.mark_points(guest[0].ravel(), guest[1].ravel())   # re-marked by every scan
            else:
                layers.clear_obstacles()
        return hook

    nav, layers = make_nav(planner_patience=2.0, controller_patience=2.0)
    nav.set_goal(Goal(-2.0, 3.5, 0.0), 0.0)
    res, pose, t = run(nav, Pose2D(-2.0, -0.5, math.pi / 2), hook=stays(3.0))
    assert res.outcome == "succeeded", res.text
    assert math.hypot(pose.x + 2.0, pose.y - 3.5) <= 0.05
    nav, layers = make_nav(planner_patience=2.0, controller_patience=2.0)
    nav.set_goal(Goal(-2.0, 3.5, 0.0), 0.0)
    res, _, t = run(nav, Pose2D(-2.0, -0.5, math.pi / 2), t_max=200.0, hook=stays(1e9))
    assert res.outcome == "aborted" and t > 2.0, (res.text, t)
    assert "obstacle" in res.text, res.text


def test_goal_in_unknown_and_off_map_abort() -> None:
    for goal, words in [(Goal(3.0, 3.0, 0.0), "unknown"), (Goal(9.0, 0.0, 0.0), "off the map")]:
        nav, _ = make_nav()
        nav.set_goal(goal, 0.0)
        res, _, t = run(nav, Pose2D(-2.0, 0.0, 0.0))
        assert res.outcome == "aborted" and words in res.text and t < 1.0


def test_unreachable_goal_aborts_within_5_s() -> None:
    nav, layers = make_nav()
    # enclose the goal with static walls
    layers.static[96:104, 136:144] = 0
    layers.static[90:110, 130] = 254
    layers.static[90:110, 150] = 254
    layers.static[90, 130:151] = 254
    layers.static[110, 130:151] = 254
    layers._master = None
    nav.set_goal(Goal(2.0, 0.0, 0.0), 0.0)
    res, _, t = run(nav, Pose2D(-2.0, 0.0, 0.0))
    assert res.outcome == "aborted" and "unreachable" in res.text and t < 5.0


def test_new_obstacle_on_path_triggers_replan_and_is_avoided() -> None:
    nav, layers = make_nav()
    nav.set_goal(Goal(-2.0, 3.5, 0.0), 0.0)
    dropped = {}

    def hook(t: float, pose: Pose2D) -> None:
        # a box lands on the straight path once the robot is on its way
        if t >= 1.0 and "done" not in dropped:
            xs, ys = np.meshgrid(np.linspace(-2.4, -1.6, 17), np.linspace(1.6, 2.0, 9))
            layers.mark_points(xs.ravel(), ys.ravel())
            dropped["done"] = True
        if "done" in dropped:
            dropped["min"] = min(dropped.get("min", 9.0), float(layers.master().cost_at(pose.x, pose.y)))
            assert layers.master().cost_at(pose.x, pose.y) < 253, f"robot entered an obstacle at {pose}"

    res, pose, _ = run(nav, Pose2D(-2.0, -0.5, math.pi / 2), hook=hook)
    assert res.outcome == "succeeded", res.text
    assert math.hypot(pose.x + 2.0, pose.y - 3.5) <= 0.05


def test_blocked_forever_recovers_then_aborts() -> None:
    nav, layers = make_nav(controller_patience=2.0, planner_patience=1.0)
    nav.set_goal(Goal(-2.0, 3.5, 0.0), 0.0)
    box = np.meshgrid(np.linspace(-4.9, 4.9, 197), np.linspace(2.4, 2.8, 9))

    def hook(t: float, pose: Pose2D) -> None:
        # an obstacle line across the whole half-room that comes back after every clearing
        layers.mark_points(box[0].ravel(), box[1].ravel())

    res, _, t = run(nav, Pose2D(-2.0, -0.5, math.pi / 2), t_max=200.0, hook=hook)
    assert res.outcome == "aborted"
    assert "recovery behaviours exhausted" in res.text or "unreachable" in res.text


def test_cancel_stops() -> None:
    nav, _ = make_nav()
    nav.set_goal(Goal(2.0, 0.0, 0.0), 0.0)
    nav.step(0.0, Pose2D(-2.0, 0.0, 0.0))
    nav.cancel()
    res = nav.step(0.1, Pose2D(-2.0, 0.0, 0.0))
    assert (res.v, res.w, res.state) == (0.0, 0.0, "idle")


class StuckController:
    """A controller that claims to follow but never moves the robot (forces oscillation)."""

    def __init__(self) -> None:
        self.resets = 0

    def set_path(self, points, goal_yaw) -> None:
        pass

    def reset(self) -> None:
        self.resets += 1

    def compute(self, pose, t, costmap):
        from chefbot_navigation.controller import Command
        return Command(0.0, 0.0, "following")


def test_oscillation_runs_recoveries_in_order_then_aborts() -> None:
    layers = LayeredCostmap(room(), CostmapParams())
    layers.mark_points(np.array([-3.0]), np.array([-3.0]))    # a scan obstacle for 'clear costmaps' to remove
    nav = Navigator(NavigatorParams(oscillation_timeout=5.0), ControllerParams(),
                    make_planner("dijkstra", PlannerParams()), StuckController(), layers)
    nav.set_goal(Goal(-2.0, 3.5, 0.0), 0.0)
    seen = []
    res, pose, t = None, Pose2D(-2.0, -0.5, 0.0), 0.0

    def hook(t: float, pose: Pose2D) -> None:
        if nav.recovery and (not seen or seen[-1] != nav.recovery):
            seen.append(nav.recovery)

    res, pose, t = run(nav, pose, t_max=200.0, hook=hook)
    assert res.outcome == "aborted"
    assert "oscillating" in res.text and "exhausted" in res.text
    assert seen == ["rotate", "back_off"] or seen == ["clear_costmaps", "rotate", "back_off"]
    assert not layers.obstacles.any(), "clear_costmaps recovery did not clear"
    # rotate recovery turned the robot about once around; back-off moved it backwards
    assert pose.distance(Pose2D(-2.0, -0.5)) > 0.1


def test_no_usable_pose_stops_then_aborts_after_controller_patience() -> None:
    nav, _ = make_nav(controller_patience=2.0)
    nav.set_goal(Goal(2.0, 0.0, None), 0.0)
    assert nav.step(0.0, Pose2D(-2.0, 0.0, 0.0)).outcome is None
    for t in (0.1, 1.0, 2.0):
        res = nav.step(t, None, "transform map -> base_footprint is 3.00 s old")
        assert (res.v, res.w, res.outcome) == (0.0, 0.0, None)
    res = nav.step(2.2, None, "no scan within sensor_timeout 1.0 s (last never)")
    assert res.outcome == "aborted"
    assert res.text == "Stopped for 2 s: no scan within sensor_timeout 1.0 s (last never)"
    assert nav.goal is None


def test_pose_back_in_time_resets_the_stale_clock() -> None:
    nav, _ = make_nav(controller_patience=2.0)
    nav.set_goal(Goal(2.0, 0.0, None), 0.0)
    nav.step(0.0, None, "stale")
    nav.step(1.5, Pose2D(-2.0, 0.0, 0.0))       # a fresh pose in between
    assert nav.step(3.0, None, "stale").outcome is None
    assert nav.step(5.1, None, "stale").outcome == "aborted"


def test_parse_goal_and_faults() -> None:
    from chefbot_navigation.navigator import GoalError, parse_goal, pose_age_fault, scan_fault
    pose, has_yaw = parse_goal((1.0, 2.0, 0.0), (0.0, 0.0, 0.0, 0.0), "ignore_yaw")
    assert (pose.x, pose.y, has_yaw) == (1.0, 2.0, False)
    pose, has_yaw = parse_goal((1.0, 2.0, 0.0), (0.0, 0.0, 1.0, 1.0), "reject")
    assert has_yaw and abs(pose.yaw - math.pi / 2) < 1e-12
    with pytest.raises(GoalError, match="not finite"):
        parse_goal((math.nan, 0.0, 0.0), (0, 0, 0, 1), "reject")
    with pytest.raises(GoalError, match="orientation"):
        parse_goal((0.0, 0.0, 0.0), (0, 0, 0, 0), "reject")
    assert scan_fault(10.0, 9.5, 1.0) == "" and scan_fault(10.0, None, 0.0) == ""
    assert "last never" in scan_fault(10.0, None, 1.0) and "2.0 s ago" in scan_fault(10.0, 8.0, 1.0)
    assert pose_age_fault(0.4, 0.5, "map", "base") == ""
    assert "0.60 s old" in pose_age_fault(0.6, 0.5, "map", "base")


def test_stalest_link_names_the_dead_localization() -> None:
    """A dead amcl leaves map -> odom behind while odometry stays fresh: the abort names that link."""
    from chefbot_navigation.navigator import link_fault, pose_age_fault, stalest_link
    frames = {"odom": {"parent": "map", "broadcaster": "/amcl", "most_recent_transform": 80.3},
              "base_footprint": {"parent": "odom", "broadcaster": "/diff_tf", "most_recent_transform": 99.95},
              "camera_link": {"parent": "base_footprint", "broadcaster": "/rsp", "most_recent_transform": 0.0}}
    link = stalest_link(frames, "camera_link", "map", 100.0)
    assert link is not None and link[:3] == ("map", "odom", "/amcl") and abs(link[3] - 19.7) < 1e-9
    text = pose_age_fault(19.7, 0.5, "map", "base_footprint", link)
    assert "stale link map -> odom (from /amcl), not updated for 19.70 s" in text
    assert link_fault(link, 0.5).startswith("stale link map -> odom") and link_fault(link, 30.0) == ""
    assert link_fault(None, 0.5) == ""
    assert stalest_link(frames, "base_footprint", "odom", 100.0)[:2] == ("odom", "base_footprint")
    assert stalest_link({}, "base_footprint", "map", 1.0) is None          # unknown frame
    loop = {"a": {"parent": "b", "most_recent_transform": 1.0}, "b": {"parent": "a", "most_recent_transform": 2.0}}
    assert stalest_link(loop, "a", "map", 3.0)[1] == "a"                     # a cycle ends the walk


def test_huge_goal_coordinate_reads_short_in_the_reason() -> None:
    """A 1e300 coordinate used to print as a 300-digit number in the abort text."""
    nav, _ = make_nav()
    nav.set_goal(Goal(1e300, 0.0, 0.0), 0.0)
    res, _, _ = run(nav, Pose2D(-2.0, 0.0, 0.0))
    assert res.outcome == "aborted" and "off the map" in res.text
    assert "1e+300" in res.text and len(res.text) < 120, res.text


class FlippingPlanner:
    """Two equally long ways round an obstacle, alternating at every call (a symmetric table)."""

    def __init__(self) -> None:
        self.calls = 0
        self.direct = False     # True: the straight line (the obstacle is gone)

    def plan(self, costmap, start, goal):
        from chefbot_navigation.planners import Plan
        self.calls += 1
        side = 1.0 if self.calls % 2 else -1.0
        pts = np.array([start, (start[0] + 1.0, start[1] + side), (goal[0], goal[1] + side), goal])
        if self.direct:
            pts = np.array([start, goal])
        return Plan(points=pts, cells=np.zeros((0, 2)), cost=1.0, seconds=0.0)


class RecordingController(StuckController):
    def __init__(self) -> None:
        super().__init__()
        self.paths: list[np.ndarray] = []

    def set_path(self, points, goal_yaw) -> None:
        self.paths.append(np.asarray(points))


def test_periodic_replan_keeps_a_clear_path_unless_clearly_shorter() -> None:
    """Two near-equal ways round a table: a periodic replan must not flip the robot to the other side
    (it turned back after half a turn, +2 s on table_5's leg in the firmware demo); a clearly shorter
    new path is still taken."""
    layers = LayeredCostmap(room(), CostmapParams())
    ctrl, planner = RecordingController(), FlippingPlanner()
    nav = Navigator(NavigatorParams(planner_frequency=1.0, oscillation_timeout=0.0), ControllerParams(),
                    planner, ctrl, layers)
    nav.set_goal(Goal(-1.0, -3.0, 0.0), 0.0)
    pose = Pose2D(-4.0, -3.0, 0.0)
    for k in range(35):
        nav.step(k * DT, pose)
    assert planner.calls >= 3, "periodic replanning did not run"
    assert len(ctrl.paths) == 1, "the path flipped to the other side at a periodic replan"
    # a clearly shorter plan (the way straight through opened) replaces it
    planner.direct = True
    nav.step(4.6, pose)
    assert len(ctrl.paths) == 2 and len(ctrl.paths[-1]) == 2


def test_a_hold_stops_the_robot_for_as_long_as_it_lasts_then_it_drives_on() -> None:
    """The fleet's traffic rule holds a robot outside a zone: it waits far longer than every patience
    (oscillation 5 s, controller 2 s) without recovering or aborting, then reaches its goal."""
    nav, _ = make_nav(oscillation_timeout=5.0, controller_patience=2.0)
    nav.set_goal(Goal(2.0, 0.0, math.pi / 2), 0.0)
    held_at, states = None, set()

    def hook(t: float, pose: Pose2D) -> None:
        nonlocal held_at
        if 1.0 <= t < 31.0:
            nav.set_hold("waiting for zone 1, held by chefbot2")
            if held_at is None and nav.plan is not None:
                held_at = pose
            states.add(nav.status)
        elif t >= 31.0:
            nav.set_hold("")
        if held_at is not None and 2.0 <= t < 31.0:
            assert pose.distance(held_at) < 0.05, f"moved while held at t={t:.1f}"
            assert nav.recovery is None

    res, pose, t = run(nav, Pose2D(-2.0, 0.0, 0.0), hook=hook)
    assert res.outcome == "succeeded", res.text
    assert t > 31.0
    assert "waiting: waiting for zone 1, held by chefbot2" in states
    assert math.hypot(pose.x - 2.0, pose.y) <= 0.05


def test_a_hold_before_the_first_plan_still_lets_the_goal_be_planned() -> None:
    nav, _ = make_nav()
    nav.set_hold("waiting for zone 2, held by chefbot3")
    nav.set_goal(Goal(2.0, 0.0, None), 0.0)
    nav.step(0.0, Pose2D(-2.0, 0.0, 0.0))
    assert nav.plan is not None                      # the traffic rule needs the plan to decide
    res = nav.step(0.1, Pose2D(-2.0, 0.0, 0.0))
    assert (res.v, res.w, res.outcome) == (0.0, 0.0, None)


def test_another_robot_in_the_only_aisle_is_waited_behind_not_refused() -> None:
    """A fleet robot stands in the one 0.6 m aisle: planning around it is impossible, so the goal is
    planned through it (not aborted as unreachable); the robot stops short of it and drives on once
    it has gone."""
    n_x, n_y = 200, 60                   # 10 m x 3 m, origin (-5, -1.5)
    data = np.zeros((n_y, n_x), dtype=np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    data[:, 80:120] = 100                # a 2 m thick wall across x in [-1, 1] ...
    data[24:36, 80:120] = 0              # ... with a 0.6 m aisle at y in [-0.3, 0.3]
    layers = LayeredCostmap(OccupancyMap(GridInfo(0.05, n_x, n_y, -5.0, -1.5, 0.0), data),
                            CostmapParams(robot_radius=0.2, inflation_radius=0.3))
    layers.robots_layer = RobotsLayer(layers.info, RobotsLayerParams(footprint_padding=0.0), "chefbot1")
    cp = ControllerParams()
    nav = Navigator(NavigatorParams(), cp, make_planner("dijkstra", PlannerParams()),
                    make_controller("regulated_pure_pursuit", cp), layers)
    nav.set_goal(Goal(3.0, 0.0, None), 0.0)
    closest = math.inf

    def hook(t: float, pose: Pose2D) -> None:
        nonlocal closest
        if t < 15.0:
            layers.robots_layer.update(OtherRobot("chefbot2", t, 0.0, 0.0, 0.0, radius=0.2))
            closest = min(closest, math.hypot(pose.x, pose.y))
        else:
            layers.robots_layer.forget("chefbot2")
        layers.robots_layer.refresh(t)
        layers.layers_changed()

    res, pose, t = run(nav, Pose2D(-3.0, 0.0, 0.0), hook=hook)
    assert res.outcome == "succeeded", res.text
    assert t > 15.0
    assert closest >= 0.4 - 0.05, f"came {closest:.2f} m near the other robot's centre"
    assert math.hypot(pose.x - 3.0, pose.y) <= 0.05


def polyline_distance(p: Pose2D, poses: list[Pose2D]) -> float:
    """Distance (m) from ``p`` to the polyline through ``poses``."""
    a = np.array([[q.x, q.y] for q in poses[:-1]])
    b = np.array([[q.x, q.y] for q in poses[1:]])
    d = b - a
    t = np.clip(((p.x - a[:, 0]) * d[:, 0] + (p.y - a[:, 1]) * d[:, 1]) / np.maximum((d ** 2).sum(1), 1e-12), 0, 1)
    return float(np.min(np.hypot(a[:, 0] + t * d[:, 0] - p.x, a[:, 1] + t * d[:, 1] - p.y)))


def test_a_requested_retreat_backs_along_the_way_the_robot_came_then_goes_on() -> None:
    """request_retreat (a fleet's mutual block): the robot reverses retreat_distance along its own
    curved trail -- never more than a few cm off it -- then replans and reaches the goal."""
    nav, _ = make_nav(retreat_distance=0.8)
    nav.set_goal(Goal(2.0, 3.0, None), 0.0)            # round the wall's north end: a curved way
    trail_then, retreat, off = None, [], []

    def hook(t: float, pose: Pose2D) -> None:
        nonlocal trail_then
        if trail_then is None and math.hypot(pose.x - 0.0, pose.y - 2.3) < 0.3:
            trail_then = [*nav.trail, pose]
            nav.request_retreat("chefbot1 and chefbot2 block each other")
        if nav.recovery == "retreat":
            retreat.append(pose)
            off.append(polyline_distance(pose, trail_then))

    res, pose, t = run(nav, Pose2D(-2.0, 0.0, 0.0), hook=hook)
    assert res.outcome == "succeeded", res.text
    assert trail_then is not None and len(retreat) > 5
    backed = sum(a.distance(b) for a, b in zip(retreat, retreat[1:], strict=False))
    assert 0.6 <= backed <= 0.8 + 0.1
    assert max(off) < 0.03, f"left its trail by {max(off):.3f} m"
    assert math.hypot(pose.x - 2.0, pose.y - 3.0) <= 0.05


def test_a_retreat_stops_at_an_obstacle_behind_and_needs_a_trail() -> None:
    nav, layers = make_nav()
    nav.set_goal(Goal(-2.0, 1.0, None), 0.0)
    pose = Pose2D(-2.0, -1.0, math.pi / 2)
    for i in range(12):                                    # drive 0.55 m north: a straight trail
        nav.step(0.1 * i, Pose2D(pose.x, pose.y + 0.05 * i, pose.yaw))
    pose = Pose2D(-2.0, -0.45, math.pi / 2)
    layers.mark_points(np.array([-2.0]), np.array([-0.7]))    # a guest right behind
    nav.request_retreat("test")
    res = nav.step(1.3, pose)
    assert nav.recovery is None and (res.v, res.w) == (0.0, 0.0)   # stopped at once, planning again
    idle, _ = make_nav()
    idle.request_retreat("no goal")
    idle.step(0.0, pose)
    assert idle.retreat_request == ""                       # no goal: nothing to give way for, forgotten


def test_after_a_refused_narrow_aisle_the_next_goal_starts_from_its_mouth() -> None:
    """The café case: a wide robot refused at a 0.45 m aisle stays at its mouth with no room to turn;
    the next goal, in a 0.75 m aisle farther on, must still be reached (out the way it came)."""
    from chefbot_navigation.footprint import polygon_footprint
    res_ = 0.05
    info = GridInfo(res_, 160, 100, -1.0, -1.0, 0.0)          # 8 m x 5 m
    data = np.full((100, 160), 100, dtype=np.int8)

    def carve(x0: float, x1: float, y0: float, y1: float) -> None:
        data[int(round((y0 + 1) / res_)):int(round((y1 + 1) / res_)),
             int(round((x0 + 1) / res_)):int(round((x1 + 1) / res_))] = 0

    carve(-0.5, 6.5, 1.5, 3.0)                               # the corridor
    carve(1.775, 2.225, -0.5, 1.5)                           # a 0.45 m aisle
    carve(3.625, 4.375, -0.5, 1.5)                           # a 0.75 m aisle
    fp = polygon_footprint([[-0.18, -0.25], [0.18, -0.25], [0.18, 0.25], [-0.18, 0.25]])   # 0.5 m wide
    layers = LayeredCostmap(OccupancyMap(info, data), CostmapParams(
        robot_radius=fp.inscribed_radius, circumscribed_radius=fp.circumscribed_radius, inflation_radius=0.55))
    cp = ControllerParams()
    ctrl = make_controller("regulated_pure_pursuit", cp)
    ctrl.set_footprint(fp.samples(0.025))
    nav = Navigator(NavigatorParams(), cp, make_planner("dijkstra", PlannerParams(), fp.inscribed_radius),
                    ctrl, layers)
    nav.set_goal(Goal(2.0, 0.4, -math.pi / 2), 0.0)
    res, pose, _ = run(nav, Pose2D(0.0, 2.25, 0.0))
    assert res.outcome == "aborted" and "narrower than the robot" in res.text, res.text
    nav.set_goal(Goal(4.0, 0.4, -math.pi / 2), 0.0)
    res, pose, _ = run(nav, pose)
    assert res.outcome == "succeeded", res.text
    assert math.hypot(pose.x - 4.0, pose.y - 0.4) <= 0.05


def test_a_trail_of_marks_behind_a_fleet_robot_is_cleared_not_taken_for_a_wall() -> None:
    """The café case: the depth camera's point-cloud layer keeps marks where another robot drove through
    the only aisle; planning through the robot then found no path and the goal was refused at once.
    The stale marks are cleared (the cloud's too), and while another robot is about a failed plan is
    retried, not refused."""
    from chefbot_navigation.pointcloud_layer import CloudLayerParams, PointCloudLayer

    n_x, n_y = 200, 60
    data = np.zeros((n_y, n_x), dtype=np.int8)
    data[:2, :] = data[-2:, :] = data[:, :2] = data[:, -2:] = 100
    data[:, 80:120] = 100
    data[24:36, 80:120] = 0              # the 0.6 m aisle at y in [-0.3, 0.3], x in [-1, 1]
    layers = LayeredCostmap(OccupancyMap(GridInfo(0.05, n_x, n_y, -5.0, -1.5, 0.0), data),
                            CostmapParams(robot_radius=0.2, inflation_radius=0.3))
    layers.robots_layer = RobotsLayer(layers.info, RobotsLayerParams(footprint_padding=0.0), "chefbot1")
    layers.cloud_layer = PointCloudLayer(layers.info, CloudLayerParams())
    row, col = layers.info.world_to_cell(np.array([0.3, 0.5, 0.7]), np.zeros(3))
    layers.cloud_layer.grid[row, col] = True     # where the other robot was a moment ago
    cp = ControllerParams()
    nav = Navigator(NavigatorParams(), cp, make_planner("dijkstra", PlannerParams()),
                    make_controller("regulated_pure_pursuit", cp), layers)
    nav.set_goal(Goal(-3.0, 0.0, None), 0.0)

    def hook(t: float, pose: Pose2D) -> None:
        if t < 6.0:                      # in the aisle, leaving it westwards, slowly
            layers.robots_layer.update(OtherRobot("chefbot2", t, -0.2 - 0.02 * t, 0.0, math.pi, radius=0.2))
        else:
            layers.robots_layer.forget("chefbot2")
        layers.robots_layer.refresh(t)
        layers.layers_changed()

    states: list[str] = []
    say = nav._say
    nav._say = lambda status: (states.append(status), say(status))       # every status, not just the last
    res, pose, t = run(nav, Pose2D(3.0, 0.0, math.pi), hook=hook)
    assert res.outcome == "succeeded", res.text
    assert not any(s.startswith("recovering") for s in states), states      # cleared at once, no recovery
    assert not layers.cloud_layer.grid.any()
    assert math.hypot(pose.x + 3.0, pose.y) <= 0.05


class SqueezedController:
    """The real controller, except that from ``t0`` to ``t1`` it reports the path ahead blocked by the
    static map at ``where`` (the squeeze beside a chair that planning round another robot led into)."""

    def __init__(self, inner, t0: float, t1: float, where: tuple[float, float]) -> None:
        self.inner, self.t0, self.t1, self.where = inner, t0, t1, where

    def __getattr__(self, name):
        return getattr(self.inner, name)

    def compute(self, pose, t, costmap):
        from chefbot_navigation.controller import Command
        if self.t0 <= t <= self.t1:
            return Command(0.0, 0.0, "blocked", "obstacle ahead on the path", self.where)
        return self.inner.compute(pose, t, costmap)


@pytest.mark.parametrize("other_robot", [True, False])
def test_squeezed_against_the_map_beside_another_robot_backs_out_instead_of_aborting(other_robot: bool) -> None:
    """Two robots head-on at the hotel's 1.0 m chair pinch (a bench run): planned round the other robot,
    one was squeezed against a chair, the map blocked its path, and after 5 s it aborted the goal as 'an
    aisle narrower than the robot'.  Beside another robot it backs out the way it came and plans afresh;
    with no robot about, the same block is still a passage narrower than the robot (aborted)."""
    layers = LayeredCostmap(room(), CostmapParams())
    layers.robots_layer = RobotsLayer(layers.info, RobotsLayerParams(footprint_padding=0.0), "chefbot1")
    cp = ControllerParams()
    ctrl = SqueezedController(make_controller("regulated_pure_pursuit", cp), 3.0, 10.0, (0.0, -2.0))
    nav = Navigator(NavigatorParams(), cp, make_planner("dijkstra", PlannerParams()), ctrl, layers)
    nav.set_goal(Goal(3.0, -3.0, None), 0.0)
    escapes = []

    def hook(t: float, pose: Pose2D) -> None:
        if other_robot and t < 11.0:     # beside it, 0.7 m to its right
            layers.robots_layer.update(OtherRobot("chefbot2", t, pose.x + 0.3, pose.y - 0.63, 0.0, radius=0.2))
        else:
            layers.robots_layer.forget("chefbot2")
        layers.robots_layer.refresh(t)
        layers.layers_changed()
        if nav.recovery == "escape" and (not escapes or escapes[-1] < t - 0.2):
            escapes.append(t)

    res, pose, t = run(nav, Pose2D(-3.0, -3.0, 0.0), hook=hook)
    if other_robot:
        assert res.outcome == "succeeded", res.text
        assert escapes and 4.9 <= escapes[0] <= 5.6, escapes      # after SQUEEZE_WAIT blocked
        assert math.hypot(pose.x - 3.0, pose.y + 3.0) <= 0.05
    else:
        assert res.outcome == "aborted" and "aisle narrower than the robot at (0.00, -2.00)" in res.text, res.text
        assert not escapes and 8.0 <= t <= 8.6
