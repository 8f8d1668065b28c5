"""Launch files and the RViz config of chefbot_vision (no master)."""
import xml.etree.ElementTree as ET
from pathlib import Path

import pytest
import yaml

PKG = Path(__file__).resolve().parents[2]
LAUNCH = sorted(PKG.glob("launch/**/*.launch")) + sorted(PKG.glob("launch/**/*.launch.xml")) + \
    sorted(PKG.glob("test/*.test"))


def test_expected_files():
    names = {p.name for p in LAUNCH}
    assert {"cv_bridge_demo.launch", "cam.launch", "image_read.launch", "view_pointcloud.launch",
            "depth_to_cloud.launch.xml"} <= names


@pytest.mark.parametrize("path", LAUNCH, ids=lambda p: p.name)
def test_every_arg_has_doc(path):
    root = ET.parse(path).getroot()
    passed_down = {id(a) for inc in root.iter("include") for a in inc.iter("arg")}   # values for an include
    for arg in (a for a in root.iter("arg") if id(a) not in passed_down):
        assert arg.get("doc"), f"{path.name}: <arg name='{arg.get('name')}'> has no doc="


def test_pointcloud_rviz():
    cfg = yaml.safe_load((PKG / "rviz" / "pointcloud.rviz").read_text())
    vm = cfg["Visualization Manager"]
    assert vm["Global Options"]["Fixed Frame"] == "camera_link"
    shown = {(d["Class"], d.get("Topic") or d.get("Image Topic")) for d in vm["Displays"]}
    assert {("rviz/PointCloud2", "camera/depth_registered/points"), ("rviz/PointCloud2", "camera/depth/points"),
            ("rviz/LaserScan", "scan"), ("rviz/Image", "camera/rgb/image_raw")} <= shown
