#!/usr/bin/env python3
"""rostest node for faults_files.test: corrupt files given to the launch files, the GUI and the demo.

Each case runs as a user would (``roslaunch`` / ``rosrun`` / ``python tools/demo.py``) against this
test's master, in its own process group that is always killed afterwards, and must end by itself
with a status != 0 and a message naming the corrupt file, without a Python traceback.
Covered elsewhere, not repeated: map_server with a corrupt / non-UTF-8 / oversized YAML and a missing
image (chefbot_navigation map_server.test, node level), bad parameter values of every node
(bad_params.test, move_base.test test_m, chefbot_sim unit/test_node_params.py), world-file parse errors
(chefbot_sim unit/test_world.py), a non-UTF-8 tables file for the GUI (chefbot_gui unit/test_no_master.py),
the deliver CLI's bad tables (chefbot_navigation unit tests).
"""
from __future__ import annotations

import os
import re
import tempfile
import unittest
from pathlib import Path

import rospkg
import rospy
import rostest

from chefbot_common.rostest_helpers import first_traceback, run_in_group

PKG = "chefbot_tests"
TIMEOUT = 90.0      # s wall per case: the launch must have ended by itself by then
ROOT = Path(rospkg.RosPack().get_path("chefbot_tests")).parent


class FaultsFilesTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.tmp = tempfile.TemporaryDirectory(prefix="faults_files_")
        d = Path(cls.tmp.name)
        cls.bad_world = d / "bad_world.yaml"
        cls.bad_world.write_text("name: broken\nobjects:\n  - {name: table, shape: box, size: [1, 1\n")
        cls.bad_map_yaml = d / "bad_map.yaml"
        cls.bad_map_yaml.write_text("image: map.pgm\nresolution: [0.05\norigin: [0, 0, 0]\n")
        cls.bad_pgm = d / "garbage.pgm"
        cls.bad_pgm.write_bytes(b"P5\n# truncated\n40 40\n255\n" + bytes(range(97)))     # 1600 bytes promised
        cls.bad_pgm_yaml = d / "garbage_map.yaml"
        cls.bad_pgm_yaml.write_text("image: garbage.pgm\nresolution: 0.05\norigin: [0, 0, 0]\nnegate: 0\n"
                                    "occupied_thresh: 0.65\nfree_thresh: 0.196\n")
        cls.bad_params = d / "bad_move_base.yaml"
        cls.bad_params.write_text("controller_frequency: 10.0\ncontroller: {max_vel_x: 0.35\n")
        cls.bad_tables = d / "bad_tables.yaml"
        cls.bad_tables.write_text("frame: map\nposes:\n  home: {x: 0.0, y: 0.0, yaw: 0.0\n  table_1: [2.05\n")
        cls.no_destinations = d / "home_only_tables.yaml"    # valid YAML, nothing to deliver to
        cls.no_destinations.write_text("frame: map\nposes:\n  home: {x: 0.0, y: 0.0, yaw: 0.0}\n")

    @classmethod
    def tearDownClass(cls) -> None:
        cls.tmp.cleanup()

    def check(self, what: str, cmd: list[str], bad: Path, env: dict[str, str] | None = None,
              required: str = "") -> None:
        """``required``: the launch's required node that must die on the file.  roslaunch itself exits 0
        when a required node dies (ROS 1's roslaunch, not ours), so then the node's own exit code is
        checked in roslaunch's "REQUIRED process ... has died" report, and that the launch ended."""
        rc, out = run_in_group(cmd, TIMEOUT, env)
        tail = out[-1500:]
        died = re.search(rf"REQUIRED process \[{required}-\d+\] has died!\s*process has died \[pid \d+, "
                         rf"exit code (-?\d+)", out) if required else None
        code = int(died.group(1)) if died else rc
        launch = f" (roslaunch {rc})" if required else ""
        print(f"[figure] {what}: exit {code}{launch}: "
              f"{[ln for ln in out.splitlines() if str(bad) in ln][:1]}", flush=True)
        self.assertIsNotNone(rc, f"{what}: still running after {TIMEOUT:.0f} s with a corrupt {bad.name}")
        if required:
            self.assertIsNotNone(died, f"{what}: no 'REQUIRED process [{required}...] has died':\n{tail}")
        self.assertNotEqual(code, 0, f"{what}: exit 0 with a corrupt {bad.name}:\n{tail}")
        self.assertIn(str(bad), out, f"{what}: the message does not name {bad}:\n{tail}")
        # also none from a sibling node that roslaunch stops (amcl while importing or waiting for the map)
        self.assertFalse(first_traceback(out), f"{what}: a traceback: {first_traceback(out)}")

    def test_a_sim_with_a_corrupt_world(self) -> None:
        self.check("sim, corrupt world", ["roslaunch", "--disable-title", "chefbot_sim", "chefbot_hotel_world.launch",
                                          f"world:={self.bad_world}"], self.bad_world, required="chefbot_sim")

    def test_b_map_server_launch_with_a_corrupt_map_yaml(self) -> None:
        self.check("map_server.launch, corrupt map YAML",
                   ["roslaunch", "--disable-title", "chefbot_navigation", "map_server.launch",
                    f"map_file:={self.bad_map_yaml}"], self.bad_map_yaml, required="map_server")

    def test_c_amcl_launch_with_a_corrupt_pgm(self) -> None:
        self.check("amcl.launch, truncated PGM", ["roslaunch", "--disable-title", "chefbot_navigation", "amcl.launch",
                                                  f"map_file:={self.bad_pgm_yaml}"], self.bad_pgm,
                   required="map_server")

    def test_d_move_base_launch_with_corrupt_params(self) -> None:
        self.check("move_base.launch, corrupt params YAML",
                   ["roslaunch", "--disable-title", "chefbot_navigation", "move_base.launch",
                    f"params:={self.bad_params}"], self.bad_params)

    def test_e_gui_with_a_corrupt_tables_file(self) -> None:
        env = dict(os.environ, QT_QPA_PLATFORM="offscreen")
        self.check("robot_gui, corrupt tables", ["rosrun", "chefbot_gui", "robot_gui", "__name:=bad_tables_gui",
                                                 f"_tables_file:={self.bad_tables}"], self.bad_tables, env)

    def test_f_demo_with_a_corrupt_tables_file(self) -> None:
        env = dict(os.environ, CHEFBOT_DEMO_TABLES_FILE=str(self.bad_tables))
        self.check("make demo, corrupt tables", ["python3", str(ROOT / "tools" / "demo.py")], self.bad_tables, env)


    def test_g_demo_and_gui_with_a_tables_file_without_destinations(self) -> None:
        env = dict(os.environ, CHEFBOT_DEMO_TABLES_FILE=str(self.no_destinations))
        self.check("make demo, no destinations", ["python3", str(ROOT / "tools" / "demo.py")],
                   self.no_destinations, env)
        self.check("robot_gui, no destinations", ["rosrun", "chefbot_gui", "robot_gui", "__name:=no_dest_gui",
                                                  f"_tables_file:={self.no_destinations}"], self.no_destinations,
                   dict(os.environ, QT_QPA_PLATFORM="offscreen"))


if __name__ == "__main__":
    rospy.init_node("faults_files_test", disable_signals=True)
    rostest.rosrun(PKG, "faults_files", FaultsFilesTest)
