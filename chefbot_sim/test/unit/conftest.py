"""Shared fixtures of chefbot_sim's unit tests (no ROS master)."""
from pathlib import Path

import pytest

PKG = Path(__file__).resolve().parents[2]


@pytest.fixture(scope="session")
def urdf() -> str:
    """The ChefBot URDF with its <chefbot_sim> block, expanded once per session."""
    from chefbot_description.model import expand_xacro
    return expand_xacro()


@pytest.fixture(scope="session")
def pkg() -> Path:
    return PKG
