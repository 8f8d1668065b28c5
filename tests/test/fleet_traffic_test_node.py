#!/usr/bin/env python3
"""rostest node for fleet_traffic.test: two ChefBots in the café's single-lane aisles.

1. Head-on: chefbot1 delivers to ``~table`` at the end of a dead-end aisle one robot wide; then, at
   once, chefbot1 is sent back to its parking pose (out of the aisle) and chefbot2 to the same table
   (into it). With chefbot_fleet's traffic rule chefbot2 waits outside the aisle's zone until
   chefbot1 is out, and both arrive: both SUCCEEDED, never both robots in the zone at once (ground
   truth against the zone computed from the map), no bumper contact, chefbot2 reported waiting.
2. A dead robot: chefbot1 is sent to ``~other_table`` in the same zone, where chefbot2 stands; once
   chefbot1 waits for chefbot2's zone, chefbot2's amcl is killed (its pose goes stale; the launch
   goes on: a fleet robot's nodes are not required); chefbot1 waits until the traffic rule's timeout
   frees the zone, then arrives (more than the timeout after the kill).  (Killing first and timing
   from there measured the drive to the aisle, not the wait: with the zone's area the aisle itself,
   chefbot1 reached its holding spot after the timeout had already freed the zone.)
"""
from __future__ import annotations

import math
import subprocess
import threading
import unittest

import rospy
import rostest
from fleet_world_test_node import Robot
from std_msgs.msg import String

from chefbot_common.fleet_file import load_fleet
from chefbot_common.map_io import load_map
from chefbot_common.rostest_helpers import wait_for
from chefbot_common.tables import load_tables
from chefbot_fleet.zones import ZoneConfig, extract_zones

PKG = "chefbot_tests"
CFG = ZoneConfig()


class FleetTrafficTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.fleet = {r.name: r for r in load_fleet(rospy.get_param("~fleet_file"))}
        cls.tables = load_tables(rospy.get_param("~tables"))
        cls.table = rospy.get_param("~table")
        cls.zones = extract_zones(load_map(rospy.get_param("~map_file")), CFG)
        cls.one, cls.two = Robot("chefbot1"), Robot("chefbot2")
        cls.lock = threading.Lock()
        cls.states: list[str] = []
        cls.both_inside = 0
        rospy.Subscriber("/chefbot2/move_base/navigation_state", String, cls.on_state, queue_size=50)
        for r in (cls.one, cls.two):
            assert r.client.wait_for_server(rospy.Duration(180.0)), f"no /{r.name}/move_base"
            wait_for(lambda r=r: r.pose is not None, 60.0, f"{r.name} ground truth", stop=rospy.is_shutdown)
        rospy.Timer(rospy.Duration(0.05), cls.watch)

    @classmethod
    def on_state(cls, msg: String) -> None:
        with cls.lock:
            cls.states.append(msg.data)

    @classmethod
    def in_zone(cls, robot: Robot, zone: int) -> bool:
        x, y = robot.xy()
        d = min((math.hypot(x - cx, y - cy) for cx, cy in cls.zone_cells(zone)), default=math.inf)
        return d <= CFG.robot_radius - 0.02     # the body overlaps the zone's area (2 cm for noise)

    @classmethod
    def zone_cells(cls, zone: int):
        info = cls.zones.info
        cells = cls.zones.zones[zone - 1].cells
        xs, ys = info.cell_to_world(cells[:, 0], cells[:, 1])
        return zip(xs, ys, strict=True)

    @classmethod
    def watch(cls, _event) -> None:
        zone = getattr(cls, "zone", 0)
        if zone and cls.in_zone(cls.one, zone) and cls.in_zone(cls.two, zone):
            with cls.lock:
                cls.both_inside += 1

    def test_1_head_on_in_a_single_lane_aisle_both_arrive_one_after_the_other(self) -> None:
        goal = self.tables[self.table]
        zone = self.zones.zone_at(goal.x, goal.y)
        self.assertTrue(zone, f"{self.table} is not in a single-lane zone of the map")
        self.one.go(self, goal, f"to {self.table}")
        type(self).zone = zone
        park = self.fleet["chefbot1"].parking
        results = {}

        def go(robot, target, what):
            try:
                robot.go(self, target, what)
                results[robot.name] = "ok"
            except AssertionError as exc:
                results[robot.name] = str(exc)

        threads = [threading.Thread(target=go, args=(self.one, park, "out to its parking pose")),
                   threading.Thread(target=go, args=(self.two, goal, f"into {self.table}"))]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        self.assertEqual(results, {"chefbot1": "ok", "chefbot2": "ok"})
        with self.lock:
            both, states = self.both_inside, list(self.states)
        self.assertEqual(both, 0, "both robots were in the aisle's zone at once")
        self.assertTrue(any(s.startswith(f"waiting: waiting for zone {zone}") for s in states),
                        f"chefbot2 never waited for zone {zone}: {states}")
        self.assertEqual((self.one.contacts, self.two.contacts), (0, 0), "a bumper was pressed")
        type(self).zone = 0    # from here on the zone may hold a dead robot and a live one

    def test_2_a_robot_whose_stack_died_in_a_zone_loses_it_after_the_timeout(self) -> None:
        goal = self.tables[self.table]
        other = self.tables[rospy.get_param("~other_table")]
        zone = self.zones.zone_at(goal.x, goal.y)
        self.assertEqual(self.zones.zone_at(other.x, other.y), zone, "~other_table must lie in ~table's zone")
        self.assertTrue(self.in_zone(self.two, zone), "chefbot2 is not in the zone (test 1 left it there)")
        with self.lock:
            self.states.clear()
        states1: list[str] = []
        sub = rospy.Subscriber("/chefbot1/move_base/navigation_state", String, lambda m: states1.append(m.data),
                               queue_size=50)
        # chefbot1 heads for the zone; once it waits for chefbot2's zone, chefbot2's localization dies
        result: dict[str, str] = {}

        def drive() -> None:
            try:
                self.one.go(self, other, "into the zone chefbot2 died in")
                result["chefbot1"] = "ok"
            except AssertionError as exc:
                result["chefbot1"] = str(exc)

        def waiting() -> bool:
            return any(s.startswith(f"waiting: waiting for zone {zone}, held by chefbot2") for s in states1)

        driver = threading.Thread(target=drive, daemon=True)
        driver.start()
        try:
            wait_for(waiting, 180.0, "chefbot1 to wait for chefbot2's zone",
                     stop=lambda: not driver.is_alive() or rospy.is_shutdown())
        except AssertionError:
            self.fail(f"chefbot1 never waited for chefbot2's zone: {states1} {result}")
        out = subprocess.run(["rosnode", "kill", "/chefbot2/amcl"], capture_output=True, text=True, timeout=30)
        self.assertEqual(out.returncode, 0, out.stdout + out.stderr)
        t0 = rospy.get_time()
        driver.join()
        took = rospy.get_time() - t0
        sub.unregister()
        self.assertEqual(result, {"chefbot1": "ok"})
        timeout = rospy.get_param("/traffic/timeout", 10.0)
        self.assertGreater(took, timeout, f"chefbot1 arrived {took:.1f} s after chefbot2 died, before the "
                                          f"{timeout:g} s timeout")
        self.assertEqual(self.one.contacts, 0, "chefbot1's bumper was pressed")


if __name__ == "__main__":
    rospy.init_node("fleet_traffic_test")
    rostest.rosrun(PKG, "fleet_traffic_test", FleetTrafficTest)
