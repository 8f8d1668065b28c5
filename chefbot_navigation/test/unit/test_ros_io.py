"""Message conversions (need the message packages, not a master)."""
from __future__ import annotations

import io
import math

import numpy as np
import pytest

nav_msgs = pytest.importorskip("nav_msgs.msg")

import genpy  # noqa: E402

from chefbot_common.geometry import Pose2D  # noqa: E402
from chefbot_common.grid import GridInfo, OccupancyMap  # noqa: E402
from chefbot_navigation.ros_io import (  # noqa: E402
    msg_to_occupancy,
    occupancy_to_msg,
    path_to_msg,
    pose2d_to_transform,
    transform_to_pose2d,
)


def test_occupancy_grid_serialises_and_round_trips() -> None:
    data = np.array([[-1, 0, 100], [50, 0, -1]], dtype=np.int8)
    occ = OccupancyMap(GridInfo(0.05, 3, 2, -1.0, 2.0, 0.0), data)
    msg = occupancy_to_msg(occ, genpy.Time(1, 0), "map")
    buf = io.BytesIO()
    msg.serialize(buf)                      # int8[] must serialise (values -1..100)
    back = nav_msgs.OccupancyGrid()
    back.deserialize(buf.getvalue())
    occ2 = msg_to_occupancy(back)
    np.testing.assert_array_equal(occ2.data, data)
    assert occ2.info == occ.info


def test_bad_grid_size_rejected() -> None:
    msg = nav_msgs.OccupancyGrid()
    msg.info.width, msg.info.height, msg.info.resolution = 3, 3, 0.05
    msg.data = [0] * 4
    with pytest.raises(ValueError, match="expected 3 x 3"):
        msg_to_occupancy(msg)


def test_transform_and_path() -> None:
    p = Pose2D(1.0, -2.0, 0.5)
    q = transform_to_pose2d(pose2d_to_transform(p, None, "map", "odom"))
    assert (q.x, q.y, q.yaw) == pytest.approx((p.x, p.y, p.yaw))
    path = path_to_msg(np.array([[0.0, 0.0], [1.0, 0.0], [1.0, 1.0]]), None, None, "map")
    assert len(path.poses) == 3 and path.header.frame_id == "map"


def test_footprint_to_msg_places_the_polygon_at_the_robot_pose() -> None:
    """move_base's ``~local_costmap/footprint``: robot-frame vertices rotated by yaw, shifted by x, y."""
    from chefbot_navigation.footprint import Footprint
    from chefbot_navigation.ros_move_base import footprint_to_msg

    fp = Footprint(np.array([[0.2, -0.1], [0.2, 0.1], [-0.2, 0.1], [-0.2, -0.1]]))
    msg = footprint_to_msg(fp, Pose2D(1.0, 2.0, math.pi / 2), genpy.Time(5), "map")
    assert msg.header.frame_id == "map" and msg.header.stamp == genpy.Time(5)
    got = np.array([[p.x, p.y] for p in msg.polygon.points])
    # (0.2, -0.1) turned 90° left is (0.1, 0.2), then + (1, 2)
    np.testing.assert_allclose(got, [[1.1, 2.2], [0.9, 2.2], [0.9, 1.8], [1.1, 1.8]], atol=1e-6)
