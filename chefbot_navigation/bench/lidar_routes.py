"""Fixed routes driven in the pybullet simulator with a 2-D lidar, recorded for the SLAM benchmarks (no ROS).

A :class:`Recording` holds, per lidar scan (10 Hz of sim time): the stamp (s), the simulator's wheel
odometry pose (the noisy wheel model of chefbot_sim/param/sim.yaml, as the robot would report it), the
ranges (m; +inf: no return within range_max, REP 117) and the true pose of base_footprint in the world;
plus the beam angles and the laser frame's pose in base_footprint from the robot model (what tf gives).

Sites (``SITES``): the hotel (``worlds/hotel.yaml``: one loop round all the tables, then back west
through the two middle aisles, ending where it started) and the corridor (``worlds/corridor.yaml``:
22 m of corridor to the east room, a lap round its table, back to the west room and a lap round its
table, ending where it started).  Lidars (``LIDARS``): 360 deg / 360 beams (the model's ``lidar:=360``
unit) and 180 deg / 180 beams (the real logs' kind; the ``lidar:=270`` sector unit's frame).

The route is followed by :func:`bench_amcl.go_to` on ground truth (the test harness, which the SLAM
never sees), its commands limited to move_base's accelerations -- or not (``careless=True``: a
keyboard driver's steps from full speed to a spin on the spot, in which the wheels slip and the
wheel odometry counts several degrees of turn that did not happen).  The same site, lidar, seed and
drive give the same recording.
"""
from __future__ import annotations

import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))

from bench_amcl import SimRig, go_to

from chefbot_common.geometry import Pose2D

V_MAX = 0.35          # m/s along the route
# command rate limits, those of move_base's controller (chefbot_navigation/param/move_base.yaml acc_lim_x,
# acc_lim_theta): without them the robot goes from 0.35 m/s straight to a 1 rad/s spin at each corner within one
# 25 ms command and slides on, wheels slipping: the wheel odometry then counted 7-9 deg of turn for 1-2 deg
ACC_LIM = 0.8         # m/s^2
ACC_LIM_THETA = 3.0   # rad/s^2
CONTROL_STEPS = 6     # physics steps (1/240 s) per command: 40 Hz
PASS_RADIUS = 0.15    # m: a waypoint within this is passed (the last one is stopped at within 0.03 m)
LEG_SLACK = 30.0      # s a leg may take beyond its length at V_MAX / 2 before the drive counts as stuck


@dataclass(frozen=True)
class Site:
    """A world of chefbot_sim/worlds, the start pose and the route's waypoints (x, y in m, world frame)."""

    world: str
    start: Pose2D
    route: tuple[tuple[float, float], ...]


@dataclass(frozen=True)
class Lidar:
    """A scanner: field of view (deg), beams, and the model's ``lidar`` xacro arg giving its frame."""

    fov: float
    beams: int
    model: str


SITES = {
    # round the tables in the outer aisles (y = -4.45, x = 10.8, y = 4.45), then east along y = 1.5, back west
    # along y = -1.5 and home: 58 m
    "hotel": Site("hotel.yaml", Pose2D(0.0, 0.0, 0.0),
                  ((1.5, -4.45), (10.8, -4.45), (10.8, 4.45), (1.5, 4.45), (1.5, 1.5), (10.5, 1.5), (10.5, -1.5),
                   (1.5, -1.5), (0.0, 0.0))),
    # down the corridor on its centre line, a lap round the east room's table, back, a lap round the west
    # room's table: 70 m
    "corridor": Site("corridor.yaml", Pose2D(0.0, 0.0, 0.0),
                     ((25.0, 0.0), (25.0, -1.5), (28.0, -1.5), (28.0, 1.6), (25.0, 1.6), (25.0, 0.0), (0.0, 0.0),
                      (0.0, 2.1), (-2.4, 2.1), (-2.4, 0.0), (0.0, 0.0))),
}
LIDARS = {"360": Lidar(360.0, 360, "360"), "180": Lidar(180.0, 180, "270")}
LIDAR_RATE = 10.0     # Hz; divides the 50 Hz of the odometry and the ground truth, so each scan has both at its instant


@dataclass
class Recording:
    """One drive: per scan ``t`` (N,) s, ``odom`` / ``truth`` (N, 3) x, y, yaw (m, rad), ``ranges`` (N, beams) m,
    ``leg``; ``angles`` (beams,) rad in the laser frame, whose pose in base_footprint is ``laser``."""

    site: str
    lidar: str
    seed: int
    t: np.ndarray
    odom: np.ndarray
    truth: np.ndarray
    ranges: np.ndarray
    angles: np.ndarray
    range_min: float
    range_max: float
    laser: Pose2D
    leg: np.ndarray            # (N,) index of the waypoint the robot was heading for (where along the route)
    wall_s: float = 0.0        # s of wall time the drive took

    @property
    def length(self) -> float:
        """m driven (true path between scans)."""
        return float(np.hypot(*np.diff(self.truth[:, :2], axis=0).T).sum())

    def save(self, path: Path) -> None:
        """Write an ``.npz`` (``load`` reads it back)."""
        np.savez_compressed(path, site=self.site, lidar=self.lidar, seed=self.seed, t=self.t, odom=self.odom,
                            truth=self.truth, ranges=self.ranges, angles=self.angles,
                            limits=(self.range_min, self.range_max), laser=(self.laser.x, self.laser.y, self.laser.yaw),
                            leg=self.leg, wall_s=self.wall_s)

    @classmethod
    def load(cls, path: Path) -> Recording:
        z = np.load(path)
        return cls(str(z["site"]), str(z["lidar"]), int(z["seed"]), z["t"], z["odom"], z["truth"], z["ranges"],
                   z["angles"], float(z["limits"][0]), float(z["limits"][1]), Pose2D(*map(float, z["laser"])),
                   z["leg"], float(z["wall_s"]))


def record(site: str, lidar: str, seed: int = 0, route: tuple[tuple[float, float], ...] | None = None,
           careless: bool = False) -> Recording:
    """Drive ``SITES[site]``'s route (or ``route``) with ``LIDARS[lidar]``; the simulator's noise seed ``seed``;
    ``careless``: the commands are not rate-limited (the wheels slip in the turns).

    Raises RuntimeError naming the leg when the robot does not reach a waypoint in time (stuck)."""
    s, lid = SITES[site], LIDARS[lidar]
    wall0 = time.monotonic()
    rig = SimRig(s.start, seed, world=s.world, xacro_args={"lidar": lid.model}, lidar_fov=lid.fov,
                 lidar_beams=lid.beams, lidar_rate=LIDAR_RATE)
    sim = rig.sim
    for kind in ("depth", "cliff"):
        sim.set_enabled(kind, False)
    laser = rig.frame_in_base(sim.lidar.frame)
    odom = truth = None
    v = w = 0.0
    dt = CONTROL_STEPS * sim.options.time_step
    rows_t, rows_odom, rows_truth, rows_ranges, rows_leg = [], [], [], [], []
    waypoints = list(route if route is not None else s.route)
    try:
        here = rig.truth()
        for k, (x, y) in enumerate(waypoints):
            last = k == len(waypoints) - 1
            limit = sim.time + math.hypot(x - here.x, y - here.y) / (V_MAX / 2) + LEG_SLACK
            while True:
                here = rig.truth()
                cmd = go_to(here, x, y, reach=0.03 if last else PASS_RADIUS, v_max=V_MAX, stop=last)
                if cmd is None:
                    break
                if sim.time > limit:
                    raise RuntimeError(f"{site}: leg {k} to ({x}, {y}) not reached by {sim.time:.0f} s sim "
                                       f"(robot at {here.x:.2f}, {here.y:.2f})")
                if careless:
                    v, w = cmd
                else:
                    v += float(np.clip(cmd[0] - v, -ACC_LIM * dt, ACC_LIM * dt))
                    w += float(np.clip(cmd[1] - w, -ACC_LIM_THETA * dt, ACC_LIM_THETA * dt))
                sim.set_cmd_vel(v, w)
                for e in sim.step(CONTROL_STEPS):
                    if e.kind == "odom":
                        odom = (e.stamp, e.data["x"], e.data["y"], e.data["yaw"])
                    elif e.kind == "ground_truth":
                        truth = (e.stamp, e.data["x"], e.data["y"], e.data["yaw"])
                    elif e.kind == "lidar":
                        if odom is None or truth is None or odom[0] != e.stamp or truth[0] != e.stamp:
                            raise RuntimeError(f"no odometry / ground truth at the scan's instant {e.stamp:.4f} s")
                        rows_t.append(e.stamp)
                        rows_odom.append(odom[1:])
                        rows_truth.append(truth[1:])
                        rows_ranges.append(e.data["ranges"])
                        rows_leg.append(k)
        return Recording(site, lidar, seed, np.array(rows_t), np.array(rows_odom), np.array(rows_truth),
                         np.array(rows_ranges, dtype=np.float32), sim.lidar.angles(), sim.lidar.range_min,
                         sim.lidar.range_max, laser, np.array(rows_leg), time.monotonic() - wall0)
    finally:
        sim.close()
