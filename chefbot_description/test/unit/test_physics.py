"""pybullet loads the model and it drives like a differential-drive robot.

Only the wheels and casters touch the floor; equal wheel speeds move it
forward (+x), opposite speeds turn it counter-clockwise when the right wheel
leads. Physics is stepped a fixed number of times (no wall clock).
"""
from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path

import pytest

from chefbot_description import model

pybullet = pytest.importorskip("pybullet")
bullet_client = pytest.importorskip("pybullet_utils.bullet_client")

DT = 1.0 / 240.0  # s, pybullet's default step
STALL_TORQUE = 18 * 9.80665 / 100  # N*m, 18 kg*cm (book)


@pytest.fixture()
def sim(urdf_xml: str, tmp_path: Path) -> Iterator[tuple]:
    client = bullet_client.BulletClient(connection_mode=pybullet.DIRECT)
    try:
        client.setGravity(0, 0, -9.81)
        client.setTimeStep(DT)
        plane = client.createMultiBody(0, client.createCollisionShape(pybullet.GEOM_PLANE))
        urdf = tmp_path / "chefbot.urdf"
        urdf.write_text(model.urdf_for_physics(urdf_xml))
        body = client.loadURDF(str(urdf), [0, 0, 0], flags=pybullet.URDF_USE_INERTIA_FROM_FILE)
        joints = {client.getJointInfo(body, j)[12].decode(): j for j in range(client.getNumJoints(body))}
        yield client, plane, body, joints
    finally:
        client.disconnect()


def step(client, seconds: float) -> None:
    for _ in range(round(seconds / DT)):
        client.stepSimulation()


def touching(client, body: int, plane: int, joints: dict[str, int]) -> set[str]:
    names = {j: n for n, j in joints.items()}
    return {names.get(c[3], "base_footprint") for c in client.getContactPoints(body, plane)}


def drive(client, body: int, joints: dict[str, int], left: float, right: float) -> None:
    for link, speed in (("wheel_left_link", left), ("wheel_right_link", right)):
        client.setJointMotorControl2(body, joints[link], pybullet.VELOCITY_CONTROL,
                                     targetVelocity=speed, force=STALL_TORQUE)


def test_mass_in_pybullet_matches_model(sim, robot: model.RobotModel) -> None:
    client, _, body, joints = sim
    masses = [client.getDynamicsInfo(body, j)[0] for j in [-1, *joints.values()]]
    assert sum(masses) == pytest.approx(model.total_mass(robot), abs=1e-3)


def test_rests_on_wheels_and_casters_only(sim) -> None:
    client, plane, body, joints = sim
    step(client, 1.0)
    contacts = touching(client, body, plane, joints)
    assert {"wheel_left_link", "wheel_right_link"} <= contacts
    assert contacts & {"caster_front_link", "caster_back_link"}
    assert contacts <= {"wheel_left_link", "wheel_right_link", "caster_front_link", "caster_back_link"}
    (x, y, z), _ = client.getBasePositionAndOrientation(body)
    assert abs(z) < 0.005  # settles on the floor, no sinking or bouncing


def test_equal_wheel_speeds_drive_forward(sim) -> None:
    client, plane, body, joints = sim
    step(client, 0.5)
    wheel_speed = 5.0  # rad/s -> 0.225 m/s
    drive(client, body, joints, wheel_speed, wheel_speed)
    step(client, 2.0)
    (x, y, _), q = client.getBasePositionAndOrientation(body)
    v = client.getBaseVelocity(body)[0]
    assert v[0] == pytest.approx(wheel_speed * 0.045, rel=0.1)
    assert x > 0.3 and abs(y) < 0.02
    assert abs(client.getEulerFromQuaternion(q)[2]) < math.radians(3)
    assert touching(client, body, plane, joints) <= {"wheel_left_link", "wheel_right_link",
                                                     "caster_front_link", "caster_back_link"}


def test_opposite_wheel_speeds_turn_in_place(sim) -> None:
    client, _, body, joints = sim
    step(client, 0.5)
    drive(client, body, joints, -3.0, 3.0)
    step(client, 1.0)
    (x, y, _), _ = client.getBasePositionAndOrientation(body)
    yaw_rate = client.getBaseVelocity(body)[1][2]
    assert yaw_rate == pytest.approx(2 * 3.0 * 0.045 / 0.30, rel=0.15)  # v_r - v_l over the track
    assert math.hypot(x, y) < 0.03
