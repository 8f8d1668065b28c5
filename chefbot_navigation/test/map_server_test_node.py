#!/usr/bin/env python3
"""rostest node for map_server.test: the served map equals the file; bad files fail loudly."""
from __future__ import annotations

import os
import subprocess
import tempfile
import threading
import unittest

import numpy as np
import rospy
import rostest
from nav_msgs.msg import MapMetaData, OccupancyGrid
from nav_msgs.srv import GetMap

from chefbot_common.map_io import load_map
from chefbot_navigation.ros_io import msg_to_occupancy

PKG = "chefbot_navigation"


def wait_for_message(topic: str, cls, timeout: float):
    """First message on a (latched) topic within ``timeout`` wall seconds, else None."""
    got: list = []
    ev = threading.Event()

    def cb(msg) -> None:
        got.append(msg)
        ev.set()

    sub = rospy.Subscriber(topic, cls, cb, queue_size=1)
    ev.wait(timeout)
    sub.unregister()
    return got[0] if got else None


def run_map_server(yaml_path: str, *extra: str) -> subprocess.CompletedProcess:
    """Run a second map_server under another name on a bad file; it must exit by itself."""
    return subprocess.run(["rosrun", PKG, "map_server", yaml_path, "__name:=bad_map_server",
                           "map:=bad_map", "map_metadata:=bad_map_metadata", "static_map:=bad_static_map",
                           *extra],
                          capture_output=True, text=True, timeout=60, check=False)


class MapServerTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.fixtures = rospy.get_param("/fixture_dir")
        cls.expected = load_map(os.path.join(cls.fixtures, "room.yaml"))

    def test_map_is_latched_and_equal_to_file(self) -> None:
        msg = wait_for_message("map", OccupancyGrid, 30.0)
        self.assertIsNotNone(msg, "no latched map")
        self.assertEqual(msg.header.frame_id, "map")
        occ = msg_to_occupancy(msg)
        np.testing.assert_array_equal(occ.data, self.expected.data)
        self.assertEqual(occ.info, self.expected.info)
        meta = wait_for_message("map_metadata", MapMetaData, 30.0)
        self.assertIsNotNone(meta, "no latched map_metadata")
        self.assertEqual((meta.width, meta.height), (self.expected.info.width, self.expected.info.height))

    def test_map_file_param_inside_namespace(self) -> None:
        msg = wait_for_message("second/map", OccupancyGrid, 30.0)
        self.assertIsNotNone(msg, "no map in namespace 'second'")
        np.testing.assert_array_equal(msg_to_occupancy(msg).data, self.expected.data)
        rospy.wait_for_service("second/static_map", 30.0)

    def test_static_map_service_equals_topic(self) -> None:
        rospy.wait_for_service("static_map", 30.0)
        resp = rospy.ServiceProxy("static_map", GetMap)()
        occ = msg_to_occupancy(resp.map)
        np.testing.assert_array_equal(occ.data, self.expected.data)
        self.assertAlmostEqual(resp.map.info.resolution, 0.05, places=6)

    def test_map_saver_round_trip(self) -> None:
        with tempfile.TemporaryDirectory() as tmp:
            base = os.path.join(tmp, "saved")
            out = subprocess.run(["rosrun", PKG, "map_saver", "-f", base], capture_output=True, text=True,
                                 timeout=60, check=False)
            self.assertEqual(out.returncode, 0, out.stderr)
            back = load_map(base + ".yaml")
            np.testing.assert_array_equal(back.data, self.expected.data)
            self.assertEqual(back.info, self.expected.info)

    def test_bad_field_exits_nonzero_naming_file_and_field(self) -> None:
        path = os.path.join(self.fixtures, "bad_resolution.yaml")
        out = run_map_server(path)
        self.assertNotEqual(out.returncode, 0)
        self.assertIn(path, out.stderr)
        self.assertIn("'resolution'", out.stderr)

    def test_missing_image_exits_nonzero_naming_file(self) -> None:
        out = run_map_server(os.path.join(self.fixtures, "missing_image.yaml"))
        self.assertNotEqual(out.returncode, 0)
        self.assertIn("/nonexistent/chefbot/room.pgm", out.stderr)
        self.assertIn("'image'", out.stderr)

    def test_map_over_max_map_cells_exits_nonzero_without_traceback(self) -> None:
        path = os.path.join(self.fixtures, "room.yaml")
        out = run_map_server(path, "_max_map_cells:=10")
        self.assertNotEqual(out.returncode, 0)
        self.assertIn(path, out.stderr)
        self.assertIn("max_map_cells", out.stderr)
        self.assertNotIn("Traceback", out.stderr)

    def test_non_utf8_yaml_exits_nonzero_without_traceback(self) -> None:
        with tempfile.NamedTemporaryFile("wb", suffix=".yaml", delete=False) as f:
            f.write("image: carte_\xe9t\xe9.pgm\n".encode("latin-1"))
        try:
            out = run_map_server(f.name)
            self.assertNotEqual(out.returncode, 0)
            self.assertIn(f.name, out.stderr)
            self.assertIn("not UTF-8", out.stderr)
            self.assertNotIn("Traceback", out.stderr)
        finally:
            os.unlink(f.name)

    def test_corrupt_yaml_exits_nonzero(self) -> None:
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as f:
            f.write("image: [oops\n")
        try:
            out = run_map_server(f.name)
            self.assertNotEqual(out.returncode, 0)
            self.assertIn(f.name, out.stderr)
        finally:
            os.unlink(f.name)


if __name__ == "__main__":
    rospy.init_node("map_server_test")
    rostest.rosrun(PKG, "map_server", MapServerTest)
