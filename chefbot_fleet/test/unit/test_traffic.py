"""The traffic rule in the loop: robots following plans through a single-lane corridor (kinematic, pure)."""
from __future__ import annotations

import numpy as np
import pytest
from test_zones import two_rooms

from chefbot_common.geometry import Pose2D
from chefbot_fleet.traffic import TrafficConfig, TrafficRule
from chefbot_fleet.zones import ZoneConfig, extract_zones

ZCFG = ZoneConfig()
STEP = 0.05            # m a robot moves per cycle


def line(x0: float, x1: float, y: float = 3.0) -> np.ndarray:
    n = int(abs(x1 - x0) / 0.05) + 1
    return np.stack([np.linspace(x0, x1, n), np.full(n, y)], axis=1)


def drive(rule: TrafficRule, plans: dict[str, np.ndarray], cycles: int = 2000, dead: dict | None = None):
    """Move every robot STEP along its plan per cycle unless held; returns (per-robot index reached,
    per-robot cycles held, the most robots inside the zone at once)."""
    idx = dict.fromkeys(plans, 0)
    held = dict.fromkeys(plans, 0)
    most_inside = 0
    dead = dead or {}
    for k in range(cycles):
        now = k * 0.1
        inside = 0
        for name, plan in plans.items():
            i = idx[name]
            pose = Pose2D(*plan[i], 0.0)
            if rule.geom.touching(pose.x, pose.y, ZCFG.robot_radius):
                inside += 1
            if name in dead and k >= dead[name]:
                continue                          # its stack died: no updates, no motion
            reason = rule.update(name, pose, plan[i:], now)
            if reason:
                held[name] += 1
            elif i < len(plan) - 1:
                idx[name] = i + 1
        rule.expire(k * 0.1)
        most_inside = max(most_inside, inside)
        if all(idx[n] == len(p) - 1 for n, p in plans.items() if n not in dead):
            break
    return idx, held, most_inside


def test_two_robots_head_on_take_turns_and_both_arrive() -> None:
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG)
    plans = {"a": line(1.5, 7.5), "b": line(7.5, 1.5)}
    idx, held, most_inside = drive(rule, plans)
    assert idx == {"a": len(plans["a"]) - 1, "b": len(plans["b"]) - 1}
    assert most_inside == 1                      # never both in the corridor
    assert held["a"] == 0 and held["b"] > 0      # a asked first; b waited outside
    assert not rule.table.holder                 # released at the end


def test_the_waiting_robot_stops_outside_the_zone_at_the_holding_distance() -> None:
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG)
    rule.update("a", Pose2D(4.5, 3.0, 0.0), line(4.5, 7.5), 0.0)          # a is in the corridor
    assert rule.table.held_by("a") == 1
    b_plan = line(7.5, 1.5)
    for i, (x, y) in enumerate(b_plan):
        if rule.update("b", Pose2D(x, y, 0.0), b_plan[i:], 0.1 * i):
            break
    d = rule.geom.distance(1, x, y)
    assert ZCFG.hold_distance - STEP <= d <= ZCFG.hold_distance + ZCFG.hold_margin
    assert "waiting for zone 1, held by a" == rule.update("b", Pose2D(x, y, 0.0), b_plan[i:], 99.0)


def test_a_robot_whose_stack_died_in_the_corridor_loses_its_zone_after_the_timeout() -> None:
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG, TrafficConfig(timeout=5.0))
    plans = {"a": line(1.5, 7.5), "b": line(7.5, 5.2)}      # b only needs to enter the corridor's east end
    # a dies after 60 cycles (3 m: inside the corridor); b then waits until a's zone expires
    idx, held, _ = drive(rule, plans, dead={"a": 60})
    assert idx["b"] == len(plans["b"]) - 1
    assert held["b"] >= 40                      # waited about the 5 s timeout (50 cycles of 0.1 s)


def test_a_plan_leaving_the_zone_behind_releases_it() -> None:
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG)
    rule.update("a", Pose2D(3.0, 3.0, 0.0), line(3.0, 7.5), 0.0)            # books the corridor ahead
    assert rule.table.held_by("a") == 1
    rule.update("a", Pose2D(3.0, 3.0, 0.0), line(3.0, 1.0), 0.1)            # new goal: back west
    assert rule.table.held_by("a") == 0


def test_bad_settings_are_named() -> None:
    with pytest.raises(ValueError, match="lookahead"):
        TrafficConfig(lookahead=0.0)
    with pytest.raises(ValueError, match="timeout"):
        TrafficConfig(timeout=-1.0)


def test_a_zone_booked_from_outside_goes_to_a_robot_found_parked_inside_it() -> None:
    """b's pose is not known yet when a books the corridor; b stands in it without a goal."""
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG)
    assert rule.update("a", Pose2D(2.5, 3.0, 0.0), line(2.5, 7.5), 0.0) == ""
    assert rule.table.held_by("a") == 1
    assert rule.update("b", Pose2D(4.5, 3.0, 0.0), None, 0.1) == ""        # parked inside: it is the holder now
    assert rule.table.held_by("b") == 1 and rule.table.held_by("a") == 0
    assert rule.update("a", Pose2D(2.9, 3.0, 0.0), line(2.9, 7.5), 0.2) == "waiting for zone 1, held by b"
    # a robot that has entered keeps its zone: b, inside, does not take it from a, inside too
    rule2 = TrafficRule(zm, ZCFG)
    rule2.update("a", Pose2D(3.8, 3.0, 0.0), line(3.8, 7.5), 0.0)
    rule2.update("b", Pose2D(5.0, 3.0, 0.0), None, 0.1)
    assert rule2.table.held_by("a") == 1


def test_a_robot_coming_out_keeps_its_zone_until_it_is_out_of_the_apron() -> None:
    """a leaves the corridor westwards (no zone ahead): it keeps the zone until its centre is
    hold_distance from it, so b, waiting at that distance, does not drive into it."""
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG)
    rule.update("a", Pose2D(4.5, 3.0, np.pi), line(4.5, 1.0), 0.0)                 # in the corridor
    assert rule.table.held_by("a") == 1
    for x in np.arange(4.5, 1.0, -0.05):
        rule.update("a", Pose2D(float(x), 3.0, np.pi), line(float(x), 1.0), 0.1)
        d = rule.geom.distance(1, float(x), 3.0)
        if rule.table.held_by("a") == 0:
            break
    assert ZCFG.hold_distance <= d <= ZCFG.hold_distance + 0.06


def test_a_robot_making_room_from_a_zone_stops_where_it_has_released_it() -> None:
    """b stands idle in the corridor a waits for; the spot it is sent to (room_spot with the rule's
    keep-out) is past the apron, so b gives the zone up there -- a spot just outside the zone kept it
    for ever (the robot waiting was told again and again that b stood in its way)."""
    from chefbot_fleet.blocks import BlockConfig, RobotView, room_spot
    zm = extract_zones(two_rooms(0.6), ZCFG)
    rule = TrafficRule(zm, ZCFG)
    rule.update("b", Pose2D(4.5, 3.0, 0.0), None, 0.0)
    a_plan = line(2.0, 5.0)
    assert rule.update("a", Pose2D(2.9, 3.0, 0.0), a_plan, 0.1) == "waiting for zone 1, held by b"
    me = RobotView("b", 4.5, 3.0, 0.22)
    a = RobotView("a", 2.9, 3.0, 0.22, a_plan, held=True)
    x, y = room_spot(zm.clearance, zm.info, rule.keep_out(), me, [a], BlockConfig())
    assert rule.geom.distance(1, x, y) >= ZCFG.hold_distance + ZCFG.hold_margin - 0.05   # beyond the apron
    for k, f in enumerate(np.linspace(0.0, 1.0, 60)):                     # b drives there
        px, py = 4.5 + f * (x - 4.5), 3.0 + f * (y - 3.0)
        rule.update("b", Pose2D(px, py, 0.0), np.array([[px, py], [x, y]]), 0.2 + 0.1 * k)
    rule.update("b", Pose2D(x, y, 0.0), None, 99.0)
    assert rule.table.held_by("b") == 0
    assert rule.update("a", Pose2D(2.9, 3.0, 0.0), a_plan, 99.1) == ""
