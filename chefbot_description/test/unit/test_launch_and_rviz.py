"""Launch files document every argument; RViz configs are valid and show what navigation needs."""
from __future__ import annotations

import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

PKG = Path(__file__).resolve().parents[2]
LAUNCH_FILES = sorted(PKG.glob("launch/**/*.launch")) + sorted(PKG.glob("launch/**/*.launch.xml")) + \
    sorted(PKG.glob("test/*.test"))


def test_expected_launch_files_exist() -> None:
    names = {p.relative_to(PKG).as_posix() for p in LAUNCH_FILES}
    assert {"launch/upload_model.launch", "launch/view_model.launch", "launch/view_navigation.launch",
            "launch/includes/robot_state.launch.xml"} <= names


@pytest.mark.parametrize("path", LAUNCH_FILES, ids=lambda p: p.name)
def test_every_arg_has_doc(path: Path) -> None:
    root = ET.parse(path).getroot()
    assert root.tag == "launch"
    for arg in root.iter("arg"):
        if arg.get("value") is None:  # a declaration, not an <include> pass-down
            assert arg.get("doc"), f"{path.name}: <arg name={arg.get('name')!r}> has no doc="


def load_rviz(name: str) -> dict:
    config = yaml.safe_load((PKG / "rviz" / name).read_text())
    assert isinstance(config, dict) and "Visualization Manager" in config
    return config["Visualization Manager"]


def displays(vm: dict) -> dict[str, dict]:
    return {d["Name"]: d for d in vm["Displays"]}


def test_model_rviz() -> None:
    vm = load_rviz("model.rviz")
    assert vm["Global Options"]["Fixed Frame"] == "base_footprint"
    shown = displays(vm)
    assert shown["RobotModel"]["Class"] == "rviz/RobotModel"
    assert shown["RobotModel"]["Robot Description"] == "robot_description"
    assert shown["TF"]["Class"] == "rviz/TF"


def test_navigation_rviz() -> None:
    vm = load_rviz("navigation.rviz")
    assert vm["Global Options"]["Fixed Frame"] == "map"
    topics = {(d["Class"], d.get("Topic")) for d in vm["Displays"]}
    assert {("rviz/Map", "map"),
            ("rviz/Map", "move_base/global_costmap/costmap"),
            ("rviz/Map", "move_base/local_costmap/costmap"),
            ("rviz/LaserScan", "scan"),
            ("rviz/PoseArray", "particlecloud"),
            ("rviz/Path", "move_base/global_plan"),
            ("rviz/Polygon", "move_base/local_costmap/footprint"),
            ("rviz/Pose", "move_base/current_goal"),
            ("rviz/RobotModel", None)} <= topics
    tools = {(t["Class"], t.get("Topic")) for t in vm["Tools"]}
    assert {("rviz/SetInitialPose", "initialpose"), ("rviz/SetGoal", "move_base_simple/goal")} <= tools
