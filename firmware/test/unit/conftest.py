"""Builds the host library (incremental, quiet: a no-op when up to date) so the
tests always load one that matches the sources."""
from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

FIRMWARE = Path(__file__).resolve().parents[2]

try:
    import chefbot_firmware  # noqa: F401 - from the catkin devel space
except ImportError:  # plain checkout without catkin: use the source tree
    sys.path.insert(0, str(FIRMWARE / "python"))


@pytest.fixture(scope="session", autouse=True)
def host_library() -> None:
    proc = subprocess.run(["make", "-s", "-C", str(FIRMWARE), "lib"], capture_output=True, text=True)
    if proc.returncode != 0:
        pytest.fail(f"make -C firmware lib failed:\n{proc.stdout}\n{proc.stderr}")
