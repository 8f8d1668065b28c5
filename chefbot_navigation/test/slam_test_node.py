#!/usr/bin/env python3
"""rostest node for slam.test: the live node maps the played bag; bad inputs are reported, not fatal."""
from __future__ import annotations

import subprocess
import threading
import time
import unittest

import rosbag
import rosgraph
import rospy
import rostest
import tf2_ros
from diagnostic_msgs.msg import DiagnosticArray
from nav_msgs.msg import MapMetaData, OccupancyGrid
from nav_msgs.srv import GetMap
from rosgraph_msgs.msg import Log
from sensor_msgs.msg import Imu, LaserScan
from std_msgs.msg import Bool
from std_srvs.srv import SetBool

from chefbot_navigation.ros_io import msg_to_occupancy

PKG = "chefbot_navigation"


class SlamNodeTest(unittest.TestCase):
    @classmethod
    def setUpClass(cls) -> None:
        cls.logs: list[str] = []
        cls.lock = threading.Lock()
        rospy.Subscriber("/rosout", Log, cls._on_log, queue_size=100)
        cls.buffer = tf2_ros.Buffer()
        cls.listener = tf2_ros.TransformListener(cls.buffer)
        cls.maps: list[OccupancyGrid] = []
        rospy.Subscriber("map", OccupancyGrid, lambda m: cls.maps.append(m), queue_size=2)
        cls.bad_scan = rospy.Publisher("bad/scan", LaserScan, queue_size=5)
        cls.diag: dict[str, dict] = {}      # latest status of /slam, by name: {"message": ..., key: value}
        rospy.Subscriber("/diagnostics", DiagnosticArray, cls._on_diag, queue_size=20)
        cls.imu = rospy.Publisher("imu/data", Imu, queue_size=5)
        cls.bumper = rospy.Publisher("bumper", Bool, queue_size=5)
        cls.start_playback()

    @classmethod
    def start_playback(cls) -> None:
        """Unpause the bag once the slam nodes and this one listen to /tf_static and /scan: the bag's one
        /tf_static message is not latched, and a node that starts after it never learns the camera's
        pose on the base (a loaded machine started the slam node more than play's 2 s delay late)."""
        master = rosgraph.Master(rospy.get_name())
        listeners = {"/tf_static": {"/slam", "/bad/slam", rospy.get_name()}, "/scan": {"/slam"}}
        end = time.monotonic() + 120.0
        while time.monotonic() < end and not rospy.is_shutdown():
            subs = {topic: set(nodes) for topic, nodes in master.getSystemState()[1]}
            if all(want <= subs.get(topic, set()) for topic, want in listeners.items()):
                break
            time.sleep(0.2)
        rospy.wait_for_service("/play/pause_playback", timeout=60.0)
        rospy.ServiceProxy("/play/pause_playback", SetBool)(False)

    @classmethod
    def _on_log(cls, msg: Log) -> None:
        with cls.lock:
            cls.logs.append(msg.msg)

    @classmethod
    def _on_diag(cls, msg: DiagnosticArray) -> None:
        with cls.lock:
            for st in msg.status:
                if st.hardware_id == "/slam":
                    cls.diag[st.name] = {"message": st.message, "level": st.level,
                                         **{kv.key: kv.value for kv in st.values}}

    def wait(self, cond, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if cond():
                return True
            time.sleep(0.2)
        return False

    def test_1_map_tf_and_service(self):
        # the whole room is mapped once the bag (325 s at 4x) has played: judge a map published
        # within one map_update_interval of the bag's end (its /clock stops there), not the first
        # big one (under load the node is behind the 4x playback)
        with rosbag.Bag(rospy.get_param("/fixture_bag")) as bag:
            end = bag.get_end_time()
        interval = rospy.get_param("slam/map_update_interval", 2.0)

        def mapped() -> bool:
            return (bool(self.maps) and self.maps[-1].header.stamp.to_sec() >= end - interval - 0.5
                    and int((msg_to_occupancy(self.maps[-1]).data == 100).sum()) > 2000)

        def sensors() -> None:
            # the bag has no IMU or bumper: while it plays, the node gets an IMU without a valid orientation
            # (rejected, so it cannot change the map) and a released bumper, and counts both on diagnostics
            while not (done.is_set() or rospy.is_shutdown()):
                self.imu.publish(Imu())
                self.bumper.publish(Bool(False))
                time.sleep(0.1)
        done = threading.Event()
        feeder = threading.Thread(target=sensors, daemon=True)
        feeder.start()
        try:
            self.assertTrue(self.wait(mapped, 300), "no map of the room published by the end of the bag")
        finally:
            done.set()
            feeder.join(5.0)
        occ = msg_to_occupancy(self.maps[-1])
        self.assertEqual(self.maps[-1].header.frame_id, "map")
        self.assertGreater(int((occ.data == 0).sum()) * 0.05 ** 2, 140.0)     # m^2 of free space
        meta = rospy.wait_for_message("map_metadata", MapMetaData, timeout=10)
        self.assertEqual((meta.width, meta.height), (occ.info.width, occ.info.height))
        rospy.wait_for_service("dynamic_map", timeout=10)
        resp = rospy.ServiceProxy("dynamic_map", GetMap)()
        self.assertEqual(len(resp.map.data), resp.map.info.width * resp.map.info.height)
        t = self.buffer.lookup_transform("map", "odom", rospy.Time(0), rospy.Duration(5.0))
        self.assertEqual(t.child_frame_id, "odom")
        # the robot is localized in its own map: map -> base_footprint exists
        self.buffer.lookup_transform("map", "base_footprint", rospy.Time(0), rospy.Duration(5.0))
        # /diagnostics: tracking, and the odometry bias learned from the bag (its wheels count ~3 % too much
        # turn in spins: the simulated wheels slip)
        self.assertTrue(self.wait(lambda: "slam: odometry bias" in self.diag and "slam: tracking" in self.diag, 30),
                        f"no slam diagnostics: {sorted(self.diag)}")
        with self.lock:
            bias, tracking = dict(self.diag["slam: odometry bias"]), dict(self.diag["slam: tracking"])
        self.assertLess(abs(float(bias["turn_scale"]) - 0.97), 0.02, bias)
        self.assertIn("turn scale", bias["message"])
        self.assertGreater(int(tracking["matched"]), 0.9 * int(tracking["keyframes"]), tracking)
        self.assertGreater(int(tracking["imu_samples_rejected"]), 0, tracking)     # imu/data reaches the node
        self.assertGreater(int(tracking["bumper_samples"]), 0, tracking)           # and so does bumper
        self.assertEqual(int(tracking["imu_samples"]), 0, tracking)

    def test_2_bad_inputs_are_reported(self):
        # bad/slam (odom_frame no_such_odom, scans on bad/scan): each bad scan gets a message naming the problem
        def scan(frame: str, beams: int) -> LaserScan:
            m = LaserScan()
            m.header.frame_id = frame
            m.angle_min, m.angle_increment, m.range_min, m.range_max = -0.5, 0.01, 0.1, 5.0
            m.ranges = [1.0] * beams
            return m

        def sent_and_logged(msg: LaserScan, text: str) -> bool:
            msg.header.stamp = rospy.Time.now()
            self.bad_scan.publish(msg)
            with self.lock:
                return any(text in m for m in self.logs)
        self.assertTrue(self.wait(lambda: sent_and_logged(scan("no_such_laser", 10), "frame 'no_such_laser'"), 60))
        self.assertTrue(self.wait(lambda: sent_and_logged(scan("camera_depth_frame", 0), "zero beams"), 60))
        self.assertTrue(self.wait(lambda: sent_and_logged(scan("camera_depth_frame", 10),
                                                          "no odometry tf no_such_odom -> base_footprint"), 60))
        names = subprocess.run(["rosnode", "list"], capture_output=True, text=True, timeout=30).stdout
        self.assertIn("/bad/slam", names)                       # still alive

    def test_3_bad_parameter_stops_the_node(self):
        r = subprocess.run(["rosrun", PKG, "slam", "__name:=slam_badparam", "__ns:=badparam", "_delta:=-1.0"],
                           capture_output=True, text=True, timeout=60, check=False)
        self.assertNotEqual(r.returncode, 0)
        self.assertIn("~delta", r.stderr)


if __name__ == "__main__":
    rospy.init_node("slam_test")
    rostest.rosrun(PKG, "slam_test", SlamNodeTest)
