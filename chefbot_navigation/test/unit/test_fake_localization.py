"""The fake-localization correction map -> odom."""
from __future__ import annotations

import pytest

from chefbot_common.geometry import Pose2D, map_to_odom, wrap_angle


def test_map_to_odom_reproduces_ground_truth() -> None:
    truth, odom = Pose2D(3.0, 1.0, 0.5), Pose2D(2.8, 1.3, 0.4)   # odometry drifted
    corr = map_to_odom(truth, odom)
    est = corr.compose(odom)
    assert (est.x, est.y) == pytest.approx((truth.x, truth.y))
    assert wrap_angle(est.yaw - truth.yaw) == pytest.approx(0.0, abs=1e-12)
