"""Cliff sensors, spawn height on platforms and the stage world (DIRECT mode, no ROS master)."""
import math

import numpy as np
import pytest
from sensor_msgs.msg import Range

from chefbot_common.geometry import Pose2D
from chefbot_common.params import ParamError
from chefbot_sim import ros_io
from chefbot_sim.node_params import cliff_topics
from chefbot_sim.sim import SENSORS, SimOptions, Simulator
from chefbot_sim.world import load_world, parse_yaml_world, surface_height

STAGE_TOP = 0.2     # m, stage.yaml
STAGE_EDGE = 2.0    # m, x of the stage's east edge
CLIFF_R = 0.145     # m, sensors from the robot's centre (chefbot_sim.xacro)
CLIFF_ANGLE = math.radians(40.0)


@pytest.fixture(scope="module")
def stage(urdf, pkg):
    s = Simulator(urdf, load_world(pkg / "worlds" / "stage.yaml"), options=SimOptions(seed=1))
    s.step(120)   # settle on the wheels
    yield s
    s.close()


def sensor_heights(sim: Simulator) -> np.ndarray:
    """True height (m) of each cliff sensor above what is under it, from the URDF block's poses."""
    pos, rot = sim.bullet.frame_pose("base_link")
    out = []
    for c in sim.params.cliffs:
        p = pos + rot @ c.pose()[:3, 3]
        out.append(p[2] - surface_height(sim.world.shapes, p[0], p[1]))
    return np.array(out)


def test_cliff_is_a_sensor_at_the_urdf_rate(stage):
    assert "cliff" in SENSORS
    assert stage.rates["cliff"] == pytest.approx(50.0)


def test_spawn_on_the_stage_and_flat_readings(stage):
    gt = stage.ground_truth()
    assert gt["position"][2] == pytest.approx(STAGE_TOP, abs=0.003)   # on the stage, not inside it
    d = stage.cliff()
    assert d["names"] == ["cliff_left", "cliff_front", "cliff_right"]
    assert d["frames"] == ["cliff_left_link", "cliff_front_link", "cliff_right_link"]
    # the URDF frame is where the block puts the sensor: x along the beam, straight down
    for c, frame in zip(stage.params.cliffs, d["frames"], strict=True):
        p_block = stage.bullet.frame_pose(c.parent)
        p_frame, r_frame = stage.bullet.frame_pose(frame)
        assert p_frame == pytest.approx(p_block[0] + p_block[1] @ c.pose()[:3, 3], abs=1e-9)
        assert r_frame[:, 0] == pytest.approx([0, 0, -1], abs=0.02)   # the base rests tilted ~0.007 rad
    # the beam reads the sensor's true height above the stage top (~0.03 m)
    assert d["range"] == pytest.approx(sensor_heights(stage), abs=1e-3)
    assert np.all((d["range"] > 0.02) & (d["range"] < 0.04))
    assert d["min_range"].tolist() == [0.01] * 3 and d["max_range"].tolist() == [0.15] * 3
    assert d["field_of_view"] == pytest.approx([math.radians(5.0)] * 3)
    assert stage._read("bumper")["pressed"] is False   # standing on the stage is not a bump


@pytest.mark.parametrize("x,expect", [
    (STAGE_EDGE - CLIFF_R - 0.01, [True, True, True]),                        # all sensors over the stage
    (STAGE_EDGE - CLIFF_R + 0.01, [True, False, True]),                       # only the front one past the edge
    (STAGE_EDGE - CLIFF_R * math.cos(CLIFF_ANGLE) + 0.01, [False, False, False]),
])
def test_readings_at_the_edge(stage, x, expect):
    stage.teleport(Pose2D(x, 0.0, 0.0))
    stage.step(2)
    r = stage.cliff()["range"]
    assert [bool(math.isfinite(v)) for v in r] == expect, r
    assert np.all(r[np.isfinite(r)] < 0.04)
    assert np.all(r[~np.isfinite(r)] == math.inf)   # REP 117: no floor within max_range


def test_events_come_at_50_hz(urdf):
    s = Simulator(urdf, parse_yaml_world("objects: []"))
    try:
        ev = [e for e in s.step(240) if e.kind == "cliff"]
        assert len(ev) == 50
        assert all(np.all(np.isfinite(e.data["range"])) for e in ev)   # flat floor
    finally:
        s.close()


def test_low_floor_step_within_reach_reads_its_depth(urdf):
    # a 5 cm step down: still within 0.15 m, the sensor reads the lower floor
    w = parse_yaml_world("objects: [{name: step, shape: box, size: [2, 2, 0.05], pose: [0, 0, 0]}]")
    s = Simulator(urdf, w, start=Pose2D(1.0 - CLIFF_R + 0.02, 0.0, 0.0))
    try:
        s.step(60)
        r = s.cliff()["range"]
        assert r[1] == pytest.approx(sensor_heights(s)[1], abs=0.002)   # down to the lower floor
        assert r[1] == pytest.approx(r[0] + 0.05, abs=0.003)              # 5 cm more than on the step
    finally:
        s.close()


def test_range_messages():
    d = {"names": ["cliff_left", "cliff_front"], "frames": ["cliff_left_link", "cliff_front_link"],
         "range": np.array([0.031, np.inf]),
         "min_range": np.array([0.01, 0.01]), "max_range": np.array([0.15, 0.15]),
         "field_of_view": np.array([0.087, 0.087])}
    msgs = ros_io.cliff_msgs(d, None)
    assert [m.header.frame_id for m in msgs] == ["cliff_left_link", "cliff_front_link"]
    assert all(m.radiation_type == Range.INFRARED for m in msgs)
    assert msgs[0].range == pytest.approx(0.031) and msgs[1].range == math.inf
    assert (msgs[0].min_range, msgs[0].max_range, msgs[0].field_of_view) == pytest.approx((0.01, 0.15, 0.087))


def test_surface_height_of_stacks_and_overhangs():
    w = parse_yaml_world("""objects:
      - {name: stage, shape: box, size: [4, 4, 0.2], pose: [0, 0, 0]}
      - {name: crate, shape: box, size: [1, 1, 0.3], pose: [1, 1, 0.2, 0]}
      - {name: shelf, shape: box, size: [1, 1, 0.05], pose: [-1, -1, 0.9, 0]}
      - {name: drum, shape: cylinder, radius: 0.3, height: 0.4, pose: [5, 5]}""")
    assert w.surface_height(0.0, 0.0) == pytest.approx(0.2)
    assert w.surface_height(1.0, 1.0) == pytest.approx(0.5)     # a crate on the stage
    assert w.surface_height(-1.0, -1.0) == pytest.approx(0.2)   # under the shelf: stays on the stage
    assert w.surface_height(5.1, 5.0) == pytest.approx(0.4)
    assert w.surface_height(9.0, 9.0) == 0.0


def test_cliff_topics_default_and_mapping():
    names = ["cliff_left", "cliff_front", "cliff_right"]
    assert cliff_topics(names, {}) == ["cliff/left", "cliff/front", "cliff/right"]
    assert cliff_topics(names, {"cliff_front": "cliff/center"}) == ["cliff/left", "cliff/center", "cliff/right"]


@pytest.mark.parametrize("mapping,match", [
    ([1], "must be a map"), ({"cliff_rear": "x"}, "cliff_rear"), ({"cliff_left": "/abs"}, "relative"),
    ({"cliff_left": ""}, "cliff_left"), ({"cliff_left": "cliff/right"}, "two sensors")])
def test_cliff_topics_errors_are_named(mapping, match):
    with pytest.raises(ParamError, match=match):
        cliff_topics(["cliff_left", "cliff_front", "cliff_right"], mapping)


def test_prefixed_model_stamps_prefixed_frames():
    # a robot in namespace chefbot1 (xacro frame_prefix): every frame the sim stamps carries the prefix
    from chefbot_description.model import expand_xacro

    s = Simulator(expand_xacro(args={"frame_prefix": "chefbot1/"}), parse_yaml_world("objects: []"))
    try:
        p = s.params
        assert s.cliff_frames == ["chefbot1/cliff_left_link", "chefbot1/cliff_front_link", "chefbot1/cliff_right_link"]
        assert (p.drive.odom_frame, p.drive.base_frame) == ("chefbot1/odom", "chefbot1/base_footprint")
        assert (p.depth_camera.depth_frame, p.imu.frame, p.ultrasonic.frame) == (
            "chefbot1/camera_depth_optical_frame", "chefbot1/gyro_link", "chefbot1/ultrasonic_link")
        ev = [e for e in s.step(24) if e.kind == "cliff"]
        assert ev and all(np.all(np.isfinite(e.data["range"])) for e in ev)   # sensors found their parent
    finally:
        s.close()
