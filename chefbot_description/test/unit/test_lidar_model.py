"""The optional 2-D lidar of the model (xacro arg lidar: none | 360 | 270), issue 30."""
from __future__ import annotations

import subprocess
from pathlib import Path

import numpy as np
import pytest

from chefbot_description import model

PLATE_TOP_SURFACE = 0.37 + 0.0025   # m above the floor (book plate centre + half its thickness)
SCAN_PLANE = PLATE_TOP_SURFACE + 0.045


@pytest.fixture(scope="module", params=["360", "270"])
def lidar_robot(request) -> tuple[str, str, model.RobotModel]:
    xml = model.expand_xacro(args={"lidar": request.param})
    return request.param, xml, model.parse_urdf(xml)


def test_default_model_has_no_lidar(robot: model.RobotModel) -> None:
    assert "laser" not in robot.links


def test_laser_frame_on_the_top_plate(lidar_robot) -> None:
    _, _, robot = lidar_robot
    assert ("base_link", "laser") in robot.edges()
    t = model.frame_transform(robot, "laser")
    np.testing.assert_allclose(t[:3, 3], [0.0, 0.0, SCAN_PLANE], atol=1e-9)
    np.testing.assert_allclose(t[:3, :3], np.eye(3), atol=1e-12)       # x forward, scan plane level
    # the body stands on the plate: its bottom on the plate surface
    geom = robot.links["laser"].collisions[0]
    bottom = t[2, 3] + geom.xyz[2] - (geom.size[1] if geom.kind == "cylinder" else geom.size[2]) / 2.0
    assert bottom == pytest.approx(PLATE_TOP_SURFACE, abs=1e-9)


def test_lidar_model_passes_check_urdf(lidar_robot, tmp_path: Path) -> None:
    _, xml, _ = lidar_robot
    urdf = tmp_path / "chefbot.urdf"
    urdf.write_text(xml)
    proc = subprocess.run(["check_urdf", str(urdf)], capture_output=True, text=True, timeout=60, check=False)
    assert proc.returncode == 0, proc.stdout + proc.stderr


def test_prefixed_laser_frame() -> None:
    robot = model.parse_urdf(model.expand_xacro(args={"lidar": "360", "frame_prefix": "chefbot1/"}))
    assert ("chefbot1/base_link", "chefbot1/laser") in robot.edges()


def test_bad_lidar_argument_fails_naming_it() -> None:
    with pytest.raises(model.XacroError, match="invalid_lidar_arg__use_none_360_or_270"):
        model.expand_xacro(args={"lidar": "180"})
