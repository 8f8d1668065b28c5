"""The <chefbot_sim> block: book values, consistency with the model, rejection of bad blocks."""
from __future__ import annotations

import math
import re

import numpy as np
import pytest

from chefbot_description import model


@pytest.fixture(scope="module")
def params(urdf_xml: str) -> model.SimParams:
    return model.load_sim_params(urdf_xml)


def test_drive_plugin_book_values(params: model.SimParams, robot: model.RobotModel) -> None:
    d = params.drive
    assert (d.left_joint, d.right_joint) == ("wheel_left_joint", "wheel_right_joint")
    assert d.wheel_separation == pytest.approx(0.30)
    assert d.wheel_diameter == pytest.approx(0.09)
    assert d.torque == pytest.approx(18.0)
    assert d.command_timeout == pytest.approx(0.6)
    assert (d.odom_frame, d.base_frame) == ("odom", "base_footprint")
    wheels = model.wheel_geometry(robot)
    assert d.wheel_radius == pytest.approx(wheels.radius)
    assert d.wheel_separation == pytest.approx(wheels.separation)


def test_depth_camera(params: model.SimParams) -> None:
    c = params.depth_camera
    assert c.depth_frame == "camera_depth_optical_frame"
    assert c.rgb_frame == "camera_rgb_optical_frame"
    assert c.update_rate == pytest.approx(10.0)
    assert c.point_cloud_cutoff == pytest.approx(0.4)
    assert (c.width, c.height) == (160, 120)
    assert math.radians(58) <= c.horizontal_fov <= math.radians(60)
    assert (c.min_range, c.max_range) == pytest.approx((0.45, 8.0))
    assert c.vertical_fov == pytest.approx(2 * math.atan(math.tan(c.horizontal_fov / 2) * 0.75))
    assert c.focal_length == pytest.approx(80.0 / math.tan(c.horizontal_fov / 2))


def test_imu(params: model.SimParams) -> None:
    assert params.imu.frame == "gyro_link"
    assert params.imu.update_rate == pytest.approx(50.0)
    assert params.imu.gyro_noise_stddev == pytest.approx(0.0014)
    assert params.imu.gyro_noise_variance == pytest.approx(0.0014 ** 2)


def test_ultrasonic(params: model.SimParams) -> None:
    u = params.ultrasonic
    assert u.frame == "ultrasonic_link"
    assert (u.min_range, u.max_range) == pytest.approx((0.02, 4.0))
    assert u.field_of_view == pytest.approx(math.radians(15))
    assert u.update_rate <= 1.0 / 0.060  # HC-SR04 needs >= 60 ms between triggers


def test_cliff_sensors(params: model.SimParams, robot: model.RobotModel) -> None:
    assert len(params.cliffs) == 3
    assert len({c.name for c in params.cliffs}) == 3
    casters = [model.frame_transform(robot, c)[:3, 3] for c in ("caster_front_link", "caster_back_link")]
    for c in params.cliffs:
        assert c.update_rate == pytest.approx(50.0)
        assert c.field_of_view == pytest.approx(math.radians(5.0))  # +-2.5 deg
        assert (c.min_range, c.max_range) == pytest.approx((0.01, 0.15))
        pose = model.frame_transform(robot, c.parent) @ c.pose()
        beam, origin = pose[:3, 0], pose[:3, 3]
        assert beam == pytest.approx([0, 0, -1], abs=1e-9)  # looks at the floor
        assert c.min_range < origin[2] < c.max_range  # sees the floor when on it
        assert math.hypot(origin[0], origin[1]) < 0.15  # under the base
        for centre in casters:  # its beam misses the caster balls
            assert math.hypot(*(origin[:2] - centre[:2])) > 0.015
        # the URDF frame the sim stamps its Range with sits exactly where the block says
        np.testing.assert_allclose(model.frame_transform(robot, f"{c.name}_link"), pose, atol=1e-12)


def test_bumper(params: model.SimParams) -> None:
    assert params.bumper.link == "base_link"


def test_astra_camera_field_of_view() -> None:
    params = model.load_sim_params(model.expand_xacro(args={"camera": "astra"}))
    assert params.depth_camera.horizontal_fov == pytest.approx(math.radians(60))


# ----------------------------------------------------------------- corrupted blocks
def corrupt(xml: str, pattern: str, replacement: str) -> str:
    new, n = re.subn(pattern, replacement, xml, count=1, flags=re.S)
    assert n == 1, f"pattern {pattern!r} not in the model"
    return new


@pytest.mark.parametrize("pattern, replacement, needle", [
    (r' torque="[^"]*"', "", r"<diff_drive>: missing attribute 'torque'"),
    (r' command_timeout="[^"]*"', ' command_timeout="soon"', r"command_timeout='soon' is not a valid float"),
    (r' wheel_diameter="[^"]*"', ' wheel_diameter="-0.09"', r"wheel_diameter='-0.09' must be > 0"),
    (r' wheel_diameter="[^"]*"', ' wheel_diameter="nan"', r"must be finite"),
    (r' width="160"', ' width="160.5"', r"<depth_camera> width='160.5' is not a valid int"),
    (r"<imu ", '<imu colour="red" ', r"<imu>: unknown attribute\(s\) colour"),
    (r"<bumper ", "<laser/><bumper ", r"unknown element <laser>"),
    (r"<bumper [^>]*/>", "", r"exactly one <bumper>, found 0"),
    (r"(<imu [^>]*/>)", r"\1\1", r"exactly one <imu>, found 2"),
    (r'<chefbot_sim version="1"', '<chefbot_sim version="2"', r"version='2'"),
    (r'left_joint="wheel_left_joint"', 'left_joint="wheel_lft_joint"', r"joint 'wheel_lft_joint'"),
    (r'frame="gyro_link"', 'frame="imu_link"', r"<imu> names link 'imu_link'"),
    (r' max_range="4.0"', ' max_range="0.01"', r"min_range 0.02 must be below max_range 0.01"),
    (r'(name="cliff_left"[^>]*) xyz="[^"]*"', r'\1 xyz="0 0"', r"cliff name='cliff_left'> xyz='0 0' is not 3 numbers"),
    (r"<chefbot_sim .*</chefbot_sim>", "", r"exactly one <chefbot_sim> element, found 0"),
])
def test_corrupted_block_is_rejected_naming_the_problem(urdf_xml: str, pattern: str, replacement: str,
                                                        needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        model.load_sim_params(corrupt(urdf_xml, pattern, replacement))


def test_model_without_sim_block_is_rejected() -> None:
    with pytest.raises(ValueError, match="sim_params:=false"):
        model.load_sim_params(model.expand_xacro(args={"sim_params": "false"}))
