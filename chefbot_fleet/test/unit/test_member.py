"""chefbot_fleet.member: which robot a fleet_member is, its fleet-file entry, its initial pose, the plan
ahead and the state text it publishes."""
from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from chefbot_common.fleet_file import FleetFileError
from chefbot_common.geometry import Pose2D
from chefbot_fleet.member import (
    COV_X,
    COV_Y,
    COV_YAW,
    find_robot,
    initial_covariance,
    pose_record,
    remaining_path,
    robot_name,
    saved_pose,
    state_text,
)

HOTEL = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps" / "hotel_fleet.yaml"


@pytest.mark.parametrize("param, ns, name", [("", "/chefbot2/", "chefbot2"), ("tray", "/chefbot2/", "tray"),
                                             ("", "chefbot3", "chefbot3")])
def test_the_robot_is_the_parameter_else_the_namespace(param: str, ns: str, name: str) -> None:
    assert robot_name(param, ns) == name


@pytest.mark.parametrize("ns", ["/", "/site/chefbot1/"])
def test_a_node_outside_one_robot_namespace_must_be_told(ns: str) -> None:
    with pytest.raises(FleetFileError, match="set ~robot"):
        robot_name("", ns)


def test_find_the_entry_or_name_the_robots() -> None:
    r = find_robot(str(HOTEL), "chefbot2")
    assert r.start == r.parking == Pose2D(0.0, -1.5, 0.0)
    with pytest.raises(FleetFileError, match="no robot 'chefbot7' .robots: chefbot1, chefbot2, chefbot3"):
        find_robot(str(HOTEL), "chefbot7")


def test_initial_covariance_is_diagonal_in_x_y_yaw() -> None:
    cov = initial_covariance(0.04, 0.01)
    assert len(cov) == 36
    assert (cov[COV_X], cov[COV_Y], cov[COV_YAW]) == (0.04, 0.04, 0.01)
    assert sum(1 for v in cov if v) == 3
    with pytest.raises(ValueError, match="> 0"):
        initial_covariance(0.0, 0.01)


def test_remaining_path_starts_at_the_nearest_point_and_stops_at_the_horizon() -> None:
    plan = np.column_stack((np.arange(0.0, 5.01, 0.05), np.zeros(101)))
    ahead = remaining_path(plan, 1.02, 0.1, 2.0)
    assert ahead[0] == pytest.approx([1.0, 0.0])
    assert ahead[-1][0] == pytest.approx(3.0, abs=0.051)        # 2 m on, the point reaching it included
    assert remaining_path(plan, 4.9, 0.0, 2.0)[-1] == pytest.approx([5.0, 0.0])     # the plan's end
    assert remaining_path(plan, 1.0, 0.0, 0.0).shape == (0, 2)
    assert remaining_path(np.zeros((0, 2)), 1.0, 0.0, 2.0).shape == (0, 2)


def test_state_text() -> None:
    assert state_text([], "") == "idle"
    assert state_text([3, 2], "chefbot2 holds aisle 1") == "idle"           # succeeded, preempted: done
    assert state_text([3, 1], "") == "driving"
    assert state_text([1], "chefbot2 holds aisle 1") == "waiting: chefbot2 holds aisle 1"


def test_a_restarted_member_resumes_from_the_pose_it_saved_and_ignores_anything_else() -> None:
    pose = Pose2D(1.23456, -2.5, 3.1)
    back = saved_pose(pose_record(pose))
    assert back is not None and abs(back.x - pose.x) < 1e-3 and back.y == -2.5 and back.yaw == 3.1
    for bad in (None, "", {}, {"x": 1.0, "y": 2.0}, {"x": "a", "y": 0, "yaw": 0}, {"x": float("nan"), "y": 0, "yaw": 0},
                [1.0, 2.0, 0.0]):
        assert saved_pose(bad) is None, bad
