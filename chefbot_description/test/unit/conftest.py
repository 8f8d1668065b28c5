"""Shared fixtures: the generated ChefBot URDF (expanded once per session)."""
from __future__ import annotations

import shutil

import pytest

from chefbot_description import model


def pytest_configure(config: pytest.Config) -> None:
    if shutil.which("xacro") is None:
        raise pytest.UsageError("the 'xacro' command is not on PATH: run through tools/with_env.sh")


@pytest.fixture(scope="session")
def urdf_xml() -> str:
    """The default model as robot_description would hold it."""
    return model.expand_xacro()


@pytest.fixture(scope="session")
def robot(urdf_xml: str) -> model.RobotModel:
    return model.parse_urdf(urdf_xml)
