"""The generated URDF against the book's figures and the frame contract.

Every number is read from the generated URDF (through chefbot_description.model),
never re-typed from the xacro; the expected values are the book's.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_description import model
from chefbot_description.model import RobotModel

PLATES = {"plate_bottom_link": 0.09, "plate_middle_link": 0.22, "plate_top_link": 0.37}  # book, m
GROUND_CONTACT = {"wheel_left_link", "wheel_right_link", "caster_front_link", "caster_back_link"}
CLEARANCE = 0.03  # book requirement: more than 3 cm ground clearance


def position(robot: RobotModel, frame: str, base: str | None = None) -> np.ndarray:
    return model.frame_transform(robot, frame, base)[:3, 3]


def lowest_point(robot: RobotModel, link: str, geom: model.Geometry) -> float:
    """Lowest z (m, base_footprint) of one collision primitive."""
    t = model.frame_transform(robot, link) @ model.pose_matrix(geom.xyz, geom.rpy)
    rot, centre_z = t[:3, :3], t[2, 3]
    if geom.kind == "sphere":
        return centre_z - geom.size[0]
    if geom.kind == "box":
        return centre_z - sum(abs(rot[2, i]) * geom.size[i] / 2.0 for i in range(3))
    if geom.kind == "cylinder":
        radius, length = geom.size
        axis_z = abs(rot[2, 2])
        return centre_z - axis_z * length / 2.0 - radius * math.sqrt(max(0.0, 1.0 - axis_z ** 2))
    raise AssertionError(f"unexpected geometry {geom.kind} on {link}")


# ----------------------------------------------------------------- frames
def test_frame_tree_is_exactly_the_contract(robot: RobotModel) -> None:
    assert robot.root == "base_footprint"
    assert robot.edges() == {(parent, child) for child, parent in model.FRAME_TREE.items()}
    assert set(robot.links) == set(model.FRAME_TREE) | {"base_footprint"}


def test_base_link_offset(robot: RobotModel) -> None:
    np.testing.assert_allclose(position(robot, "base_link"), [0.0, 0.0, 0.0102], atol=1e-9)  # book URDF


@pytest.mark.parametrize("optical", ["camera_depth_optical_frame", "camera_rgb_optical_frame"])
def test_optical_frames_follow_rep103(robot: RobotModel, optical: str) -> None:
    joint = robot.parent_joint(optical)
    np.testing.assert_allclose(joint.rpy, [-math.pi / 2, 0.0, -math.pi / 2], atol=1e-9)
    np.testing.assert_allclose(joint.xyz, [0, 0, 0], atol=1e-12)
    rot = model.frame_transform(robot, optical, "base_link")[:3, :3]
    np.testing.assert_allclose(rot[:, 2], [1, 0, 0], atol=1e-9)   # z looks forward
    np.testing.assert_allclose(rot[:, 0], [0, -1, 0], atol=1e-9)  # x to the right
    np.testing.assert_allclose(rot[:, 1], [0, 0, -1], atol=1e-9)  # y down


@pytest.mark.parametrize("frame", ["camera_link", "camera_depth_frame", "camera_rgb_frame",
                                   "gyro_link", "ultrasonic_link"])
def test_sensor_frames_are_aligned_with_base(robot: RobotModel, frame: str) -> None:
    np.testing.assert_allclose(model.frame_transform(robot, frame, "base_link")[:3, :3], np.eye(3), atol=1e-12)


def test_depth_camera_on_middle_layer(robot: RobotModel) -> None:
    z = position(robot, "camera_link")[2]
    assert z == pytest.approx(0.26)  # book dummy cube height
    assert PLATES["plate_middle_link"] < z < PLATES["plate_top_link"]
    assert position(robot, "camera_depth_optical_frame")[0] > position(robot, "camera_link")[0]


def test_ultrasonic_faces_forward_at_the_front(robot: RobotModel) -> None:
    p = position(robot, "ultrasonic_link")
    assert p[0] > 0.1 and abs(p[1]) < 1e-9
    assert p[2] > PLATES["plate_bottom_link"]


def test_gyro_on_the_rotation_axis(robot: RobotModel) -> None:
    p = position(robot, "gyro_link")
    assert abs(p[0]) < 1e-9 and abs(p[1]) < 1e-9


# ----------------------------------------------------------------- dimensions
def test_wheel_geometry_matches_book(robot: RobotModel) -> None:
    wheels = model.wheel_geometry(robot)
    assert wheels.radius == pytest.approx(0.045)
    assert wheels.width == pytest.approx(0.01)
    assert wheels.separation == pytest.approx(0.30)


@pytest.mark.parametrize("side, sign", [("left", 1.0), ("right", -1.0)])
def test_wheel_joints(robot: RobotModel, side: str, sign: float) -> None:
    joint = robot.joints[f"wheel_{side}_joint"]
    assert joint.type == "continuous"
    assert (joint.parent, joint.child) == ("base_link", f"wheel_{side}_link")
    p = position(robot, joint.child)
    assert p[0] == pytest.approx(0.0, abs=1e-12)
    assert p[1] == pytest.approx(sign * 0.15)  # left wheel at +y
    assert p[2] == pytest.approx(0.045)  # axle at wheel-radius height: the tyre touches z = 0
    # both wheels spin about +y of base_link: positive velocity drives forward
    axis = model.frame_transform(robot, joint.child, "base_link")[:3, :3] @ np.array(joint.axis)
    np.testing.assert_allclose(axis, [0, 1, 0], atol=1e-12)
    # 80 RPM, 18 kg*cm motor (book)
    assert joint.velocity == pytest.approx(80 * 2 * math.pi / 60)
    assert joint.effort == pytest.approx(18 * 9.80665 / 100)


@pytest.mark.parametrize("plate, z", sorted(PLATES.items()))
def test_plates_match_book(robot: RobotModel, plate: str, z: float) -> None:
    p = position(robot, plate)
    np.testing.assert_allclose(p, [0.0, 0.0, z], atol=1e-9)
    disc = [g for g in robot.links[plate].collisions if g.kind == "cylinder" and g.xyz == (0.0, 0.0, 0.0)]
    assert len(disc) == 1
    assert disc[0].size == pytest.approx((0.15, 0.005))  # radius, thickness


@pytest.mark.parametrize("caster, sign", [("caster_front_link", 1.0), ("caster_back_link", -1.0)])
def test_casters(robot: RobotModel, caster: str, sign: float) -> None:
    (ball,) = robot.links[caster].collisions
    assert ball.kind == "sphere"
    assert ball.size[0] == pytest.approx(0.015)
    np.testing.assert_allclose(position(robot, caster), [sign * 0.125, 0.0, 0.015], atol=1e-9)


def test_poles_between_plates(robot: RobotModel) -> None:
    for plate in ("plate_middle_link", "plate_top_link"):
        poles = [g for g in robot.links[plate].collisions if g.kind == "cylinder" and g.size[0] == 0.007]
        assert sorted((round(g.xyz[0], 6), round(g.xyz[1], 6)) for g in poles) == \
            [(-0.09, -0.09), (-0.09, 0.09), (0.09, -0.09), (0.09, 0.09)]


def test_only_wheels_and_casters_touch_the_ground(robot: RobotModel) -> None:
    for name, link in robot.links.items():
        for geom in link.collisions:
            low = lowest_point(robot, name, geom)
            if name in GROUND_CONTACT:
                assert low == pytest.approx(0.0, abs=1e-9), name
            else:
                assert low > CLEARANCE, f"{name} {geom.kind} reaches down to z = {low:.4f} m"


# ----------------------------------------------------------------- inertia
def test_every_body_has_a_plausible_inertial(robot: RobotModel) -> None:
    without = {name for name, link in robot.links.items() if link.inertial is None}
    assert without == model.VIRTUAL_FRAMES
    for name, link in robot.links.items():
        if link.inertial is None:
            assert not link.collisions, f"{name} collides but has no mass"
            continue
        inertia = link.inertial.inertia
        assert link.inertial.mass > 0, name
        np.testing.assert_allclose(inertia, inertia.T, err_msg=name)
        principal = np.linalg.eigvalsh(inertia)
        assert principal.min() > 0, f"{name}: inertia not positive definite {principal}"
        a, b, c = principal
        assert a + b >= c * (1 - 1e-9) and a + c >= b * (1 - 1e-9) and b + c >= a * (1 - 1e-9), \
            f"{name}: principal moments {principal} break the triangle inequality"


def test_total_mass_is_plausible(robot: RobotModel) -> None:
    assert 3.0 < model.total_mass(robot) < 8.0  # kg without payload; 12 kg design mass includes 2 kg + margin
    assert robot.links["base_link"].inertial.mass == pytest.approx(2.4)  # book URDF base inertial


def test_urdf_for_physics_gives_every_link_mass(urdf_xml: str) -> None:
    physics = model.parse_urdf(model.urdf_for_physics(urdf_xml))
    assert all(link.inertial is not None for link in physics.links.values())
    added = sum(physics.links[n].inertial.mass for n in model.VIRTUAL_FRAMES)
    assert added < 1e-3
    assert model.total_mass(physics) == pytest.approx(model.total_mass(model.parse_urdf(urdf_xml)), abs=1e-3)


# ----------------------------------------------------------------- parser errors
@pytest.mark.parametrize("xml, needle", [
    ("<robot", "not well-formed"),
    ("<model/>", "expected <robot>"),
    ('<robot name="r"><link name="a"/><joint name="j" type="fixed"><parent link="a"/>'
     '<child link="b"/></joint></robot>', "unknown link 'b'"),
    ('<robot name="r"><link name="a"><inertial><mass value="x"/></inertial></link></robot>', "mass"),
    ('<robot name="r"><link name="a"/><link name="a"/></robot>', "defined twice"),
])
def test_parse_urdf_rejects_bad_input(xml: str, needle: str) -> None:
    with pytest.raises(ValueError, match=needle):
        model.parse_urdf(xml)


def test_frame_transform_needs_an_ancestor(robot: RobotModel) -> None:
    with pytest.raises(ValueError, match="not an ancestor"):
        model.frame_transform(robot, "base_link", "camera_link")
