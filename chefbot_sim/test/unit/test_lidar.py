"""The optional 2-D lidar: beam geometry, REP 117 ranges, parameters, and the simulated scan (DIRECT mode,
no ROS master)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_sim import ros_io
from chefbot_sim.lidar import LidarConfig
from chefbot_sim.node_params import read_sim_params
from chefbot_sim.sim import SimConfigError, SimOptions, Simulator
from chefbot_sim.world import parse_yaml_world

LASER_Z = 0.37 + 0.0025 + 0.045   # m, scan plane above the floor: top plate surface + the unit's plane height


# ------------------------------------------------------------------ pure geometry
@pytest.mark.parametrize("fov, beams", [(360.0, 360), (360.0, 720), (270.0, 360), (270.0, 1081), (90.0, 2)])
def test_beam_angles_are_angle_min_plus_i_increment(fov: float, beams: int) -> None:
    c = LidarConfig(fov=fov, beams=beams)
    a = c.angles()
    assert len(a) == beams
    np.testing.assert_array_equal(a, c.angle_min + np.arange(beams) * c.angle_increment)
    assert c.angle_max == pytest.approx(c.angle_min + (beams - 1) * c.angle_increment)
    assert c.angle_min == pytest.approx(-math.radians(fov) / 2.0)
    d = c.directions()
    np.testing.assert_allclose(np.linalg.norm(d, axis=1), 1.0)
    np.testing.assert_array_equal(d[:, 2], 0.0)
    np.testing.assert_allclose(np.arctan2(d[:, 1], d[:, 0]), np.arctan2(np.sin(a), np.cos(a)), atol=1e-12)


def test_full_circle_has_no_beam_twice_and_a_sector_both_edges() -> None:
    full = LidarConfig(fov=360.0, beams=360)
    assert full.angle_increment == pytest.approx(math.radians(1.0))
    assert full.angle_min == pytest.approx(-math.pi)
    assert full.angle_max == pytest.approx(math.pi - math.radians(1.0))
    sector = LidarConfig(fov=270.0, beams=271)
    assert sector.angle_increment == pytest.approx(math.radians(1.0))
    assert (sector.angle_min, sector.angle_max) == pytest.approx((-math.radians(135), math.radians(135)))
    # beam 0 of a full circle points backwards, the middle beam forwards
    assert full.directions()[180] == pytest.approx([1.0, 0.0, 0.0])


def test_ranges_follow_rep117() -> None:
    c = LidarConfig(range_min=0.12, range_max=8.0, noise=0.0)
    r = c.ranges(np.array([np.inf, 0.05, 0.12, 3.0, 8.0, 8.5]))
    assert r.dtype == np.float32
    assert r[0] == np.inf          # no hit within range_max
    assert r[1] == -np.inf         # too close to measure
    assert r[2] == pytest.approx(0.12) and r[3] == pytest.approx(3.0) and r[4] == pytest.approx(8.0)
    assert r[5] == np.inf          # beyond range_max: no return


def test_noise_only_on_returns_and_seeded() -> None:
    c = LidarConfig(noise=0.01)
    d = np.r_[np.full(2000, 2.0), np.full(10, np.inf)]
    a = c.ranges(d, np.random.default_rng(4))
    b = c.ranges(d, np.random.default_rng(4))
    np.testing.assert_array_equal(a, b)
    assert np.all(a[2000:] == np.inf)
    assert float(np.std(a[:2000])) == pytest.approx(0.01, rel=0.1)
    assert float(np.mean(a[:2000])) == pytest.approx(2.0, abs=0.002)


@pytest.mark.parametrize("kw, name", [
    ({"fov": 400.0}, "lidar_fov"), ({"fov": -90.0}, "lidar_fov"), ({"fov": math.inf}, "lidar_fov"),
    ({"beams": 1}, "lidar_beams"), ({"rate": 0.0}, "lidar_rate"), ({"range_min": -0.1}, "lidar_range_min"),
    ({"range_max": 0.1}, "lidar_range_max"), ({"range_max": math.inf}, "lidar_range_max"),
    ({"noise": -0.01}, "lidar_noise"), ({"frame": ""}, "lidar_frame"),
])
def test_bad_settings_are_named(kw: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        LidarConfig(**kw).validate()


def getter(d: dict):
    return lambda name, default: d.get(name, default)


BASE = {"robot_description": "<robot name='r'/>", "~world": "/tmp/w.yaml"}


def test_params_are_read_through_the_node_spec() -> None:
    _, opts = read_sim_params(getter(BASE))
    assert opts.lidar_fov == 0.0 and opts.lidar_config() is None   # off by default
    _, opts = read_sim_params(getter({**BASE, "~lidar_fov": 270, "~lidar_beams": 541, "~lidar_rate": 15,
                                      "~lidar_range_max": 10.0, "~lidar_frame": "chefbot1/laser"}))
    c = opts.lidar_config()
    assert (c.fov, c.beams, c.rate, c.range_max, c.frame) == (270.0, 541, 15.0, 10.0, "chefbot1/laser")


@pytest.mark.parametrize("params, name", [
    ({"~lidar_fov": 361}, "lidar_fov"), ({"~lidar_fov": 360, "~lidar_beams": 1}, "lidar_beams"),
    ({"~lidar_fov": 360, "~lidar_beams": 2.5}, "lidar_beams"), ({"~lidar_fov": "wide"}, "lidar_fov"),
    ({"~lidar_fov": 360, "~lidar_rate": -10}, "lidar_rate"),
    ({"~lidar_fov": 360, "~lidar_range_min": 5, "~lidar_range_max": 4}, "lidar_range_max"),
])
def test_bad_params_stop_the_node_naming_them(params: dict, name: str) -> None:
    with pytest.raises(ValueError, match=name):
        read_sim_params(getter({**BASE, **params}))


# ------------------------------------------------------------------ the simulated scan
@pytest.fixture(scope="module")
def urdf_360() -> str:
    from chefbot_description.model import expand_xacro
    return expand_xacro(args={"lidar": "360"})


ROOM = """
objects:
  - {name: wall_east, shape: box, size: [0.2, 6.0, 1.0], pose: [3.1, 0.0, 0]}
  - {name: low_box, shape: box, size: [0.4, 0.4, 0.3], pose: [0.0, 1.5, 0]}
  - {name: leg, shape: cylinder, radius: 0.1, height: 0.7, pose: [0.0, -2.0]}
"""


@pytest.fixture(scope="module")
def room(urdf_360):
    s = Simulator(urdf_360, parse_yaml_world(ROOM), options=SimOptions(seed=2, lidar_fov=360.0, lidar_noise=0.0))
    s.step(120)
    yield s
    s.close()


def test_laser_frame_on_the_top_plate(room) -> None:
    pos, rot = room.bullet.frame_pose("laser")
    assert pos[2] == pytest.approx(LASER_Z, abs=0.005)
    np.testing.assert_allclose(rot, np.eye(3), atol=0.02)


def test_scan_sees_walls_and_tall_legs_not_low_boxes_nor_itself(room) -> None:
    d = room.lidar_scan()
    r, c = d["ranges"], room.lidar
    assert len(r) == 360 and d["frame"] == "laser"
    ang = c.angles()
    front = int(np.argmin(np.abs(ang)))
    pos, _ = room.bullet.frame_pose("laser")
    assert r[front] == pytest.approx(3.0 - pos[0], abs=0.01)              # wall face at x = 3.0
    right = int(np.argmin(np.abs(ang + math.pi / 2)))
    assert r[right] == pytest.approx(1.9 - pos[1], abs=0.02)              # the 0.7 m tall leg at y = -2
    left = int(np.argmin(np.abs(ang - math.pi / 2)))
    assert r[left] == np.inf                                             # the 0.3 m box is below the plane
    # nothing reads closer than the robot's own radius: the own body is never seen
    assert np.all(r[np.isfinite(r)] > 0.3)


def test_scan_events_at_the_rate_and_messages(room) -> None:
    t0 = room.time
    events = [e for e in room.step(240) if e.kind == "lidar"]
    assert len(events) == 10
    assert all(t0 < e.stamp <= room.time for e in events)
    m = ros_io.laser_scan_msg(events[0].data, ros_io.sim_stamp(events[0].stamp))
    assert m.header.frame_id == "laser" and len(m.ranges) == 360
    assert m.angle_min == pytest.approx(-math.pi) and m.angle_increment == pytest.approx(math.radians(1))
    assert m.angle_max == pytest.approx(m.angle_min + 359 * m.angle_increment)
    assert (m.range_min, m.range_max, m.scan_time, m.time_increment) == (0.12, 12.0, 0.1, 0.0)


def test_spawned_obstacles_are_seen(room) -> None:
    from chefbot_sim.world import parse_object
    room.spawn(parse_object({"name": "crate", "shape": "box", "size": [0.3, 0.3, 1.0], "pose": [-1.0, 0.0, 0]},
                            "test"))
    try:
        r, ang = room.lidar_scan()["ranges"], room.lidar.angles()
        back = int(np.argmin(np.abs(np.abs(ang) - math.pi)))
        pos, _ = room.bullet.frame_pose("laser")
        assert r[back] == pytest.approx(pos[0] + 0.85, abs=0.02)
    finally:
        room.remove("crate")


def test_noise_is_seeded(urdf_360) -> None:
    world = parse_yaml_world(ROOM)
    scans = []
    for _ in range(2):
        s = Simulator(urdf_360, world, options=SimOptions(seed=5, lidar_fov=270.0, lidar_beams=271))
        scans.append(s.lidar_scan()["ranges"])
        s.close()
    np.testing.assert_array_equal(scans[0], scans[1])
    assert len(scans[0]) == 271


def test_lidar_without_a_laser_frame_fails_naming_it(urdf) -> None:
    with pytest.raises(SimConfigError, match="lidar:=360"):
        Simulator(urdf, parse_yaml_world("objects: []"), options=SimOptions(lidar_fov=360.0))


def test_no_lidar_by_default(urdf) -> None:
    s = Simulator(urdf, parse_yaml_world("objects: []"), start=Pose2D(0, 0, 0))
    try:
        assert s.lidar is None and s.rates["lidar"] == 0.0
        assert not [e for e in s.step(240) if e.kind == "lidar"]
    finally:
        s.close()
