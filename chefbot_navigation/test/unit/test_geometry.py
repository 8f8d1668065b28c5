"""Poses, quaternion policies and the fake-localization correction."""
from __future__ import annotations

import math

import pytest

from chefbot_navigation.fake_localization import map_to_odom
from chefbot_navigation.geometry import Pose2D, QuaternionError, quaternion_from_yaw, wrap_angle, yaw_from_quaternion


def test_compose_inverse_round_trip() -> None:
    a, b = Pose2D(1.0, -2.0, 0.7), Pose2D(0.3, 0.4, -2.0)
    c = a.compose(b)
    back = a.inverse().compose(c)
    assert back.x == pytest.approx(b.x) and back.y == pytest.approx(b.y) and back.yaw == pytest.approx(b.yaw)


def test_map_to_odom_reproduces_ground_truth() -> None:
    truth, odom = Pose2D(3.0, 1.0, 0.5), Pose2D(2.8, 1.3, 0.4)   # odometry drifted
    corr = map_to_odom(truth, odom)
    est = corr.compose(odom)
    assert (est.x, est.y) == pytest.approx((truth.x, truth.y))
    assert wrap_angle(est.yaw - truth.yaw) == pytest.approx(0.0, abs=1e-12)


def test_quaternion_normalised_and_zero_policies() -> None:
    x, y, z, w = quaternion_from_yaw(1.0)
    assert yaw_from_quaternion(3 * x, 3 * y, 3 * z, 3 * w) == pytest.approx(1.0)
    assert yaw_from_quaternion(0, 0, 0, 0, "identity") == 0.0
    assert yaw_from_quaternion(0, 0, 0, 0, "ignore_yaw") is None
    with pytest.raises(QuaternionError, match="length zero"):
        yaw_from_quaternion(0, 0, 0, 0, "reject")
    with pytest.raises(QuaternionError, match="non-finite"):
        yaw_from_quaternion(0, 0, math.nan, 1, "identity")
