"""Core of the test-only ``fake_localization`` node (pure).

Given the robot's true pose in the map (map_T_base, from the simulator's
ground truth) and its odometry pose (odom_T_base, from tf), the map->odom
correction that makes tf's map->base_footprint equal the ground truth is
map_T_odom = map_T_base * inverse(odom_T_base).
"""
from __future__ import annotations

from chefbot_common.geometry import Pose2D


def map_to_odom(map_T_base: Pose2D, odom_T_base: Pose2D) -> Pose2D:
    """The map->odom transform (m, rad) consistent with both poses."""
    return map_T_base.compose(odom_T_base.inverse())
