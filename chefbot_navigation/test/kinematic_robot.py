"""A tiny kinematic robot for move_base rostests (imported by the test nodes; needs rospy).

It owns the clock (``/use_sim_time`` must be true): every wall tick of
``dt / rtf`` it advances sim time by ``dt``, integrates the last ``cmd_vel``
as a unicycle (0.6 s command timeout like the sim's drive plugin), and
publishes ``/clock``, tf map->odom (fixed: the start pose) and
odom->base_footprint (50 Hz), and a depth-camera-like ``scan`` (10 Hz, ray
cast into the map with its ``obstacles`` added).  Deterministic and fast.
"""
from __future__ import annotations

import math
import threading
import time

import numpy as np
import rospy
import tf2_ros
from geometry_msgs.msg import Twist
from rosgraph_msgs.msg import Clock
from sensor_msgs.msg import LaserScan

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_common.grid import OccupancyMap
from chefbot_navigation.ros_io import pose2d_to_transform

DT = 0.01               # s of sim time per step
CMD_TIMEOUT = 0.6       # s, like the sim's drive plugin
FOV = 1.2               # rad, scan field of view
RAYS = 120
RANGE_MIN, RANGE_MAX = 0.45, 6.0


class KinematicRobot:
    def __init__(self, occ: OccupancyMap, start: Pose2D, rtf: float = 1.5) -> None:
        self.occ = occ
        self.start = start
        self.rtf = rtf
        self.lock = threading.Lock()
        self.t = 1.0                     # sim time starts at 1 s (0 means "no time yet" in rospy)
        self.odom_pose = Pose2D()        # base_footprint in odom
        self.cmd = (0.0, 0.0)
        self.cmd_time = -1e9
        self.cmd_log: list[tuple[float, float, float]] = []   # (sim time, v, w)
        self.obstacles = np.zeros(occ.data.shape, dtype=bool)
        self.pub_clock = rospy.Publisher("/clock", Clock, queue_size=10)
        self.pub_scan = rospy.Publisher("scan", LaserScan, queue_size=2)
        self.tf = tf2_ros.TransformBroadcaster()
        rospy.Subscriber("cmd_vel", Twist, self.on_cmd, queue_size=10, tcp_nodelay=True)
        self.publish_scan = True          # tests switch the sensor off to check the watchdog
        self.running = True
        self.thread = threading.Thread(target=self.loop, daemon=True)
        self.thread.start()

    def on_cmd(self, msg: Twist) -> None:
        with self.lock:
            self.cmd = (msg.linear.x, msg.angular.z)
            self.cmd_time = self.t
            self.cmd_log.append((self.t, msg.linear.x, msg.angular.z))

    @property
    def pose(self) -> Pose2D:
        """True pose of base_footprint in the map."""
        with self.lock:
            return self.start.compose(self.odom_pose)

    @property
    def now(self) -> float:
        with self.lock:
            return self.t

    def velocity(self) -> tuple[float, float]:
        with self.lock:
            return self.cmd if self.t - self.cmd_time <= CMD_TIMEOUT else (0.0, 0.0)

    def add_box(self, x0: float, y0: float, x1: float, y1: float) -> None:
        info = self.occ.info
        r0, c0 = info.world_to_cell(x0, y0)
        r1, c1 = info.world_to_cell(x1, y1)
        with self.lock:
            self.obstacles[int(r0):int(r1) + 1, int(c0):int(c1) + 1] = True

    def jump_back(self, seconds: float) -> None:
        """Make sim time jump backwards (a restarted sim or bag)."""
        with self.lock:
            self.t -= seconds
            self.cmd_time = -1e9

    def stop(self) -> None:
        self.running = False
        self.thread.join(2.0)

    def loop(self) -> None:
        step = 0
        next_wall = time.monotonic()
        while self.running and not rospy.is_shutdown():
            with self.lock:
                v, w = self.cmd if self.t - self.cmd_time <= CMD_TIMEOUT else (0.0, 0.0)
                p = self.odom_pose
                th = p.yaw + w * DT
                if abs(w) < 1e-9:
                    self.odom_pose = Pose2D(p.x + v * DT * math.cos(p.yaw), p.y + v * DT * math.sin(p.yaw), p.yaw)
                else:
                    self.odom_pose = Pose2D(p.x + v / w * (math.sin(th) - math.sin(p.yaw)),
                                            p.y - v / w * (math.cos(th) - math.cos(p.yaw)), wrap_angle(th))
                self.t += DT
                t, odom_pose = self.t, self.odom_pose
            stamp = rospy.Time.from_sec(t)
            self.pub_clock.publish(Clock(clock=stamp))
            if step % 2 == 0:
                self.tf.sendTransform([pose2d_to_transform(odom_pose, stamp, "odom", "base_footprint"),
                                       pose2d_to_transform(self.start, stamp, "map", "odom")])
            if step % 10 == 0 and self.publish_scan:
                self.pub_scan.publish(self.scan(self.start.compose(odom_pose), stamp))
            step += 1
            next_wall += DT / self.rtf
            delay = next_wall - time.monotonic()
            if delay > 0:
                time.sleep(delay)
            else:
                next_wall = time.monotonic()   # running late (loaded machine): just continue

    def scan(self, pose: Pose2D, stamp) -> LaserScan:
        """Ray cast from base_footprint into map + obstacles (NaN = nothing within range_max)."""
        info = self.occ.info
        angles = np.linspace(FOV / 2, -FOV / 2, RAYS)       # leftmost first like depth_to_scan
        angles = angles[::-1]
        steps = np.arange(RANGE_MIN, RANGE_MAX, info.resolution * 0.5)
        xs = pose.x + np.cos(pose.yaw + angles)[:, None] * steps[None, :]
        ys = pose.y + np.sin(pose.yaw + angles)[:, None] * steps[None, :]
        row, col = info.world_to_cell(xs, ys)
        inside = info.inside(row, col)
        rr, cc = np.clip(row, 0, info.height - 1), np.clip(col, 0, info.width - 1)
        with self.lock:
            hit = inside & ((self.occ.data[rr, cc] >= 65) | self.obstacles[rr, cc])
        first = np.where(hit.any(axis=1), hit.argmax(axis=1), -1)
        ranges = np.where(first >= 0, steps[np.maximum(first, 0)], np.nan)
        msg = LaserScan()
        msg.header.stamp = stamp
        msg.header.frame_id = "base_footprint"
        msg.angle_min, msg.angle_max = float(angles[0]), float(angles[-1])
        msg.angle_increment = float(angles[1] - angles[0])
        msg.range_min, msg.range_max = RANGE_MIN, RANGE_MAX
        msg.ranges = ranges.astype(float).tolist()
        return msg
