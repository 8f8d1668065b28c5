"""Poses, angle wrapping and quaternion policies (chefbot_common.geometry)."""
from __future__ import annotations

import math

import pytest

from chefbot_common.geometry import Pose2D, QuaternionError, quaternion_from_yaw, yaw_from_quaternion


def test_compose_inverse_round_trip() -> None:
    a, b = Pose2D(1.0, -2.0, 0.7), Pose2D(0.3, 0.4, -2.0)
    c = a.compose(b)
    back = a.inverse().compose(c)
    assert back.x == pytest.approx(b.x) and back.y == pytest.approx(b.y) and back.yaw == pytest.approx(b.yaw)


def test_quaternion_normalised_and_zero_policies() -> None:
    x, y, z, w = quaternion_from_yaw(1.0)
    assert yaw_from_quaternion(3 * x, 3 * y, 3 * z, 3 * w) == pytest.approx(1.0)
    assert yaw_from_quaternion(0, 0, 0, 0, "identity") == 0.0
    assert yaw_from_quaternion(0, 0, 0, 0, "ignore_yaw") is None
    with pytest.raises(QuaternionError, match="length zero"):
        yaw_from_quaternion(0, 0, 0, 0, "reject")
    with pytest.raises(QuaternionError, match="non-finite"):
        yaw_from_quaternion(0, 0, math.nan, 1, "identity")


@pytest.mark.parametrize("yaw", [0.0, 0.3, math.pi / 2, -2.5, math.pi, 7.0])
def test_yaw_quaternion_is_unit_and_round_trips(yaw: float) -> None:
    q = quaternion_from_yaw(yaw)
    assert math.isclose(sum(c * c for c in q), 1.0, rel_tol=1e-12)
    assert q[0] == q[1] == 0.0
    back = yaw_from_quaternion(*q)
    assert math.isclose(math.remainder(back - yaw, 2 * math.pi), 0.0, abs_tol=1e-9)
