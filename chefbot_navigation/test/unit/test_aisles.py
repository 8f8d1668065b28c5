"""Narrow passages with the URDF footprint on a perfect unicycle (pure, no ROS): the cafe's aisles
(0.50-0.90 m) are all reached without the robot's collision bodies touching a table, within 1.5x the
time-optimal limit; a passage narrower than the robot is refused with where, within 10 s (sim time)
of the robot reaching it; replanning stays within planner_frequency while blocked."""
from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from unicycle_nav import Run, dead_end_map, slot_map

from chefbot_common.geometry import Pose2D
from chefbot_common.map_io import load_map
from chefbot_common.tables import load_tables
from chefbot_navigation.costmap import NO_INFORMATION, Costmap
from chefbot_navigation.navigator import Goal
from chefbot_navigation.time_limit import MotionLimits, profile_limit

PKG = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="module")
def urdf() -> str:
    return pytest.importorskip("chefbot_description.model").expand_xacro()


def test_cafe_every_table_reached_without_contact_within_limit(urdf: str) -> None:
    occ = load_map(PKG / "maps" / "cafe_map.yaml")
    tables = load_tables(PKG / "maps" / "cafe_tables.yaml")
    home = tables["home"]
    run = Run(occ, urdf, Pose2D(home.x, home.y, home.yaw))
    lim = MotionLimits(run.ctrl.max_vel_x, run.ctrl.max_vel_theta, run.ctrl.acc_lim_x, run.ctrl.acc_lim_x,
                       run.ctrl.acc_lim_theta)
    for name in [n for n in tables if n != "home"] + ["home"]:
        tg = tables[name]
        start_yaw = run.pose.yaw
        res, took, touches, events, _, first = run.go(Goal(tg.x, tg.y, tg.yaw))
        assert res.outcome == "succeeded", f"{name}: {res.text}; {events}"
        assert touches == 0, f"{name}: the robot's collision bodies touched the map {touches} times"
        limit = profile_limit(first.points, lim, start_yaw, tg.yaw)
        assert took <= 1.5 * limit, f"{name}: {took:.1f} s > 1.5 x {limit:.1f} s"
        assert all(a != b for a, b in zip(events, events[1:], strict=False)), events   # each change once


@pytest.mark.parametrize("width", [0.38, 0.45])
def test_passage_a_little_wider_than_the_robot_is_taken(urdf: str, width: float) -> None:
    run = Run(slot_map(width), urdf, Pose2D(1.0, 1.2, 0.0))
    res, _, touches, events, _, _ = run.go(Goal(5.0, 1.5, 0.0))
    assert res.outcome == "succeeded", f"{width} m: {res.text}; {events}"
    assert touches == 0


@pytest.mark.parametrize("width", [0.33, 0.35])
def test_passage_narrower_than_the_robot_is_refused_with_where_within_10s(urdf: str, width: float) -> None:
    run = Run(slot_map(width), urdf, Pose2D(1.0, 1.2, 0.0))
    res, took, touches, events, plans, _ = run.go(Goal(5.0, 1.5, 0.0))
    assert res.outcome == "aborted" and "aisle narrower than the robot at (2.5" in res.text, res.text
    blocked = [e for e in events if e.startswith("blocked: passage narrower than the robot at")]
    assert blocked, events
    assert touches == 0
    # the robot reaches the passage mouth at ~1.5 m / 0.35 m/s; the abort follows within 10 s of that
    assert took <= 1.5 / 0.35 + 10.0, f"refused after {took:.1f} s"
    # planner_frequency (1 Hz) bounds replanning while blocked (it used to replan every control cycle)
    span = plans[-1] - plans[0] if len(plans) > 1 else 1.0
    assert (len(plans) - 1) / span <= 1.0 + 1e-6, plans


# (aisle, gap, angle, depth) m/rad, start (x, y, yaw), the refused goal, the next goal: the robot stops
# in an aisle too narrow to turn in, at the mouth of the gap, and the next goal is back in the room.
# Before the escape (reversing along the way the robot came), backing out along the new path, which
# bends away, ran the robot into the aisle's side half way out (case 1), and a robot that had driven a
# little into the gap could not reverse at all (case 2): both aborted "aisle narrower than the robot".
DEAD_ENDS = [
    ((0.461, 0.368, 0.901, 0.515), (-0.64, -1.27, 1.97), (2.17, 2.74), (-1.05, 0.28)),
    ((0.415, 0.352, -0.555, 0.85), (-0.97, 0.97, 2.17), (2.97, -1.84), (-1.42, 1.81)),
    ((0.499, 0.369, -0.876, 0.474), (-0.57, 0.95, -2.21), (2.24, -2.69), (-1.47, 1.48)),   # wedged: brushes
    ((0.46458, 0.34910, -0.34054, 1.03074), (-1.44493, -0.18890, -0.58132), (3.29901, -1.16898),
     (-1.32684, -0.35834)),   # then turns round, touching: the turn kept its direction (it wagged)
]


@pytest.mark.parametrize("case", range(len(DEAD_ENDS)))
def test_robot_refused_in_a_dead_end_drives_out_for_the_next_goal(urdf: str, case: int) -> None:
    shape, start, refused, nxt = DEAD_ENDS[case]
    run = Run(dead_end_map(*shape), urdf, Pose2D(*start))
    res, _, touches, events, _, _ = run.go(Goal(*refused, None), t_max=120.0)
    assert res.outcome == "aborted" and "aisle narrower than the robot" in res.text, (res.text, events)
    stuck = run.pose
    res, took, touches2, events, _, _ = run.go(Goal(*nxt, None), t_max=120.0)
    assert res.outcome == "succeeded", f"from ({stuck.x:.2f}, {stuck.y:.2f}): {res.text}; {events}"
    assert touches + touches2 == 0
    assert any(e.startswith("backing out") for e in events), events


def test_trail_is_the_way_back(urdf: str) -> None:
    """Driving back along the trail shortens it (reversing out used to append the way back to it, and
    a retreat then steered to a pose in front of the robot)."""
    run = Run(slot_map(0.60), urdf, Pose2D(1.0, 1.5, 0.0))
    nav = run.nav
    for x in np.arange(1.0, 2.0, 0.01):
        nav._record(Pose2D(float(x), 1.5, 0.0))
    assert len(nav.trail) == 20 and nav.trail[-1].x == pytest.approx(1.95, abs=0.011)
    for x in np.arange(2.0, 1.5, -0.01):
        nav._record(Pose2D(float(x), 1.5, 0.0))
    assert nav.trail[-1].x == pytest.approx(1.5, abs=0.051) and len(nav.trail) <= 11


def test_an_escape_stopped_askew_turns_back_before_it_reverses(urdf: str) -> None:
    """A robot that began to turn on the spot in a dead-end aisle and was stopped part-way stands askew to
    the way it came: the escape turns it back (its back to the trail) and then reverses; a retreat (giving
    way) does not turn; the turn is bounded in time.  (A turn back that would sweep into something is
    refused by the controller's rotation check, tested above.)"""
    run = Run(slot_map(0.60), urdf, Pose2D(1.5, 1.5, 0.0))
    nav = run.nav
    for x in np.arange(0.5, 1.51, 0.01):                 # it came from the west, driving east
        nav._record(Pose2D(float(x), 1.5, 0.0))
    askew = Pose2D(1.5, 1.5, 1.2)                        # turned 69 deg left, more than the 1 rad a reverse arc takes
    nav._start_retreat(0.0, askew, "test", "escape")
    v, w, done = nav._retreat_command(0.1, askew, 3.0)
    assert not done and v == 0.0 and w < 0.0            # turning back to the right
    v, w, done = nav._retreat_command(0.2, Pose2D(1.5, 1.5, 0.3), 3.0)
    assert not done and v < 0.0                          # back to the trail: reversing along it
    nav._start_retreat(0.0, askew, "test", "retreat")
    assert nav._retreat_command(0.1, askew, 3.0)[2]       # giving way: no turning
    assert "off its back" in nav.recovery_state["ended"]  # and why it ended, for the log
    nav._start_retreat(0.0, askew, "test", "escape")
    assert nav._retreat_command(0.1 + 100.0, askew, 3.0)[2]   # not for ever
    assert "not done in" in nav.recovery_state["ended"]
    res = nav._recover(100.2, askew)                       # an ended escape says why before it plans again
    assert res.state == "planning" and any(e.startswith("recovering: escape ended (") for e in nav._events)


def test_too_narrow_for_the_inscribed_circle_is_refused_at_once(urdf: str) -> None:
    run = Run(slot_map(0.30), urdf, Pose2D(1.0, 1.2, 0.0))
    res, took, _, events, _, _ = run.go(Goal(5.0, 1.5, 0.0))
    assert res.outcome == "aborted" and "unreachable" in res.text and took <= 1.0
    assert events[0] == "planning" and events[-1].startswith("aborted: Failed to plan")


def test_turning_on_the_spot_is_checked_with_the_footprint(urdf: str) -> None:
    """In a 0.40 m passage the robot (0.30 m wide) fits straight but its camera bar (0.223 m from the
    centre) cannot swing round; in the open it can."""
    run = Run(slot_map(0.40), urdf, Pose2D(3.0, 1.5, 0.0))
    ctrl = run.nav.controller
    inside = run.layers.window(3.0, 1.5, 3.0, 3.0)
    assert ctrl.poses_collide(np.array([3.0]), np.array([1.5]), np.array([0.0]), inside)[0] is False
    hit, where = ctrl.rotation_collides(Pose2D(3.0, 1.5, 0.0), math.pi / 2, inside)
    assert hit and abs(where[1] - 1.5) > 0.19
    open_area = run.layers.window(1.2, 1.5, 3.0, 3.0)
    assert ctrl.rotation_collides(Pose2D(1.2, 1.5, 0.0), 2 * math.pi, open_area) == (False, None)
    # touching one side (mislocalised, bumped): the turn may brush what it touches, not sweep into the other
    touching = Pose2D(3.0, 1.545, 0.0)
    assert ctrl.poses_collide(np.array([3.0]), np.array([1.545]), np.array([0.0]), inside)[0]
    assert ctrl.rotation_collides(touching, math.pi / 2, inside)[0]
    assert not ctrl.rotation_collides(touching, 0.02, inside)[0]
    # at the edge of what it has seen (exploring: unknown cells beside it, nearer than the camera can see):
    # touching unknown space, it may turn into it; not touching it, a turn that sweeps into it is refused
    edge = Costmap(open_area.info, open_area.cost.copy())
    row, col = edge.info.world_to_cell(1.2, 1.5)
    edge.cost[:, int(col) + 3:] = NO_INFORMATION            # unknown from 0.15-0.2 m ahead of the centre
    assert ctrl.poses_collide(np.array([1.2]), np.array([1.5]), np.array([0.0]), edge)[0]
    assert ctrl.rotation_collides(Pose2D(1.2, 1.5, 0.0), math.pi / 2, edge) == (False, None)
    # facing away from it, clear of it, nearer than the camera bar reaches: turning round sweeps into it
    front, back = ctrl.footprint_pts[:, 0].max(), -ctrl.footprint_pts[:, 0].min()
    boundary = edge.info.origin_x + (int(col) + 3) * edge.info.resolution
    away = Pose2D(boundary - (front + back) / 2.0, 1.5, math.pi)
    assert not ctrl.poses_collide(np.array([away.x]), np.array([away.y]), np.array([away.yaw]), edge)[0]
    assert ctrl.rotation_collides(away, math.pi, edge)[0]
    ctrl.set_footprint(None)     # a round robot: turning sweeps nothing new
    assert ctrl.rotation_collides(Pose2D(3.0, 1.5, 0.0), math.pi / 2, inside) == (False, None)


def test_plan_keeps_to_the_middle_of_an_aisle(urdf: str) -> None:
    """The inflation gradient (NavFn's idea) centres the path in a 0.60 m passage (y 1.2..1.8)."""
    run = Run(slot_map(0.60), urdf, Pose2D(1.0, 1.0, 0.0))
    plan = run.nav.plan_between((1.0, 1.0), Goal(5.0, 2.0, None))
    inside = plan.points[(plan.points[:, 0] > 2.55) & (plan.points[:, 0] < 3.45)]
    assert len(inside) > 10
    assert np.max(np.abs(inside[:, 1] - 1.5)) <= 0.03, inside[:, 1]


def test_cafe_tour_with_a_wandering_estimate_never_gives_a_goal_up(urdf: str) -> None:
    """Every cafe table in turn with the navigator seeing the pose through a wandering localization error
    (about 3 cm and 0.04 rad, seeded): a turn on the spot is judged from where it started (the robot does not
    move while it turns; the estimate does), so none is "blocked" part-way.  Judged from the estimate, the turn
    round in table_s3's 0.50 m aisle for table_s4 stopped askew, both escapes ended at once ("its trail 107
    deg off its back, no room to turn back") and the goal aborted "aisle narrower than the robot" -- the
    cafe_aisles.test failure of CI, with this seed."""
    tables = load_tables(PKG / "maps" / "cafe_tables.yaml")
    home = tables["home"]
    run = Run(load_map(PKG / "maps" / "cafe_map.yaml"), urdf, Pose2D(home.x, home.y, home.yaw), jitter=(0.03, 0.04, 3))
    for name in [n for n in tables if n != "home"] + ["home"]:
        tg = tables[name]
        res, _, _, events, _, _ = run.go(Goal(tg.x, tg.y, tg.yaw), t_max=120.0)
        assert res.outcome == "succeeded", f"{name}: {res.text}; {[e for e in events if 'escape' in e]}"
