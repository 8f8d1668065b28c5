#!/usr/bin/env python3
"""rostest for calibrate_odometry.test: the guided odometry calibration on a wrongly built robot.

The simulated robot's encoders see wheels 3 % larger (left) and 1 % smaller (right) than nominal
(chefbot_sim's wheel_radius_error_*), and the drive chain is configured with a base_width 4 %
narrower than the model's 0.30 m. calibrate_odometry.launch runs as a user starts it
(roslaunch, non-interactive, the scan reference); its YAML must hold ticks_meter per wheel and
base_width near the truth, and its verify squares must close far better than the first ones.
Independently of the scan reference, the wheel ticks recorded over the whole run, dead-reckoned with
the calibrated parameters, must end far nearer the simulator's ground truth than with the old ones.
"""
import math
import subprocess
import sys
import tempfile
import time
import unittest
from pathlib import Path

import rospy
import rostest
import yaml
from nav_msgs.msg import Odometry
from std_msgs.msg import Int32

from chefbot_bringup.calibration_procedure import WheelOdometry
from chefbot_common.geometry import Pose2D, wrap_angle, yaw_from_quaternion

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from procs import group_tree, kill_group, stop_tracked

NOMINAL = 29708.0
TRUE_LEFT = NOMINAL / 1.03       # the encoders count 1/(1 + e) of the true turn
TRUE_RIGHT = NOMINAL / 0.99
TRUE_BASE = 0.30                 # the model's wheel separation (chefbot_description)
WALL_TIMEOUT = 800.0


class Record:
    """Wheel ticks (each pair when the right one arrives) and the ground truth's first and last pose."""

    def __init__(self) -> None:
        self.left: int | None = None
        self.ticks: list[tuple[int, int]] = []
        self.truth: list[Pose2D] = []
        self.subs = [rospy.Subscriber("lwheel", Int32, self._left, tcp_nodelay=True),
                     rospy.Subscriber("rwheel", Int32, self._right, tcp_nodelay=True),
                     rospy.Subscriber("ground_truth/odom", Odometry, self._truth)]

    def _left(self, m: Int32) -> None:
        self.left = m.data

    def _right(self, m: Int32) -> None:
        if self.left is not None:
            self.ticks.append((self.left, m.data))

    def _truth(self, m: Odometry) -> None:
        p, q = m.pose.pose.position, m.pose.pose.orientation
        self.truth.append(Pose2D(p.x, p.y, yaw_from_quaternion(q.x, q.y, q.z, q.w)))

    def end_error(self, left: float, right: float, base: float) -> tuple[float, float]:
        """Position (m) and heading (rad) error of the dead reckoning over the run, against the truth."""
        odo = WheelOdometry(left, right, base)
        odo.reset(self.ticks[0])
        for t in self.ticks[1:]:
            odo.update(t)
        start, end = self.truth[0], self.truth[-1]
        true = start.inverse().compose(end)
        return math.hypot(odo.x - true.x, odo.y - true.y), abs(wrap_angle(odo.yaw - true.yaw))


class TestCalibrateOdometry(unittest.TestCase):
    def test_recovers_the_parameters_and_closes_the_square(self) -> None:
        tmp = tempfile.TemporaryDirectory(prefix="calibrate_odometry_")
        self.addCleanup(tmp.cleanup)
        calib = Path(tmp.name) / "calibration.yaml"
        calib.write_text("lwheel_pid: {Kp: 400.0, Ki: 100.0, Kd: 0.0}\n")      # bringup_check's: kept
        report = Path(tmp.name) / "report.yaml"
        # wait for the drive chain (ticks) before starting, on sim time
        from std_msgs.msg import Int32
        rospy.wait_for_message("lwheel", Int32, timeout=120.0)
        rec = Record()
        rospy.wait_for_message("ground_truth/odom", Odometry, timeout=60.0)
        out = tempfile.TemporaryFile()
        proc = subprocess.Popen(["roslaunch", "--disable-title", "chefbot_bringup", "calibrate_odometry.launch",
                                 "interactive:=false", f"calibration:={calib}", f"report:={report}",
                                 "distance:=0.6", "turns:=1", "side:=0.6", "runs:=1"],
                                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
        tracked = group_tree(proc.pid)
        deadline = time.monotonic() + WALL_TIMEOUT
        while proc.poll() is None and time.monotonic() < deadline and not rospy.is_shutdown():
            tracked.update(group_tree(proc.pid))
            time.sleep(0.2)
        if proc.poll() is None:
            kill_group(proc.pid)
        proc.wait()
        stop_tracked(tracked)
        out.seek(0)
        text = out.read().decode(errors="replace")
        rospy.loginfo("calibrate_odometry output:\n%s", text[-4000:])
        self.assertTrue(report.exists(), text[-3000:])
        rep = yaml.safe_load(report.read_text())
        self.assertEqual(rep["aborted"], "", text[-3000:])
        res = rep["result"]
        cal = yaml.safe_load(calib.read_text())
        # the whole run's ticks against the ground truth: old parameters vs calibrated ones
        old = rec.end_error(NOMINAL, NOMINAL, 0.288462)
        new = rec.end_error(cal["ticks_meter_left"], cal["ticks_meter_right"], cal["base_width"])
        rospy.loginfo("calibrate_odometry: %s, E_max %.3f -> %.3f m; dead reckoning over the run (%d tick pairs): "
                      "old %.3f m / %.1f deg, calibrated %.3f m / %.1f deg", res, rep["e_max_before"],
                      rep["e_max_after"], len(rec.ticks), old[0], math.degrees(old[1]), new[0], math.degrees(new[1]))
        self.assertEqual(cal["lwheel_pid"], {"Kp": 400.0, "Ki": 100.0, "Kd": 0.0})
        # the encoders' errors are known exactly (their ratio is the wheels' diameter ratio); the rolling
        # radius and the effective base of the simulated wheels on the floor only roughly (contact,
        # casters): the scan-measured squares and the dead reckoning against the truth are the checks
        self.assertAlmostEqual(cal["ticks_meter_left"] / cal["ticks_meter_right"], TRUE_LEFT / TRUE_RIGHT, delta=0.01)
        self.assertAlmostEqual(cal["ticks_meter_left"] / TRUE_LEFT, 1.0, delta=0.02)
        self.assertAlmostEqual(cal["base_width"] / TRUE_BASE, 1.0, delta=0.05)
        self.assertLess(rep["e_max_after"], rep["e_max_before"] / 2, rep)
        self.assertLess(new[1], old[1] / 3, (old, new))
        self.assertLess(new[0], old[0] / 2, (old, new))

if __name__ == "__main__":
    rospy.init_node("test_calibrate_odometry")
    rostest.rosrun("chefbot_sim", "calibrate_odometry_sim", TestCalibrateOdometry, sys.argv)
