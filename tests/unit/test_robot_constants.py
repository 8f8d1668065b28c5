"""The robot's drive constants, written in several places, agree with each other.

Derived from the URDF (wheel radius and separation) and the motor's datasheet
figures (Pololu 37D: 64 counts per motor revolution with 4X decoding, 131.25:1
gearbox, 80 RPM free speed at 12 V), and checked against bringup's
``param/diff_drive.yaml``, the firmware's ``core/config.h`` (decoding mode) and
the board emulator (``chefbot_firmware.virtual_board``).  Also the sim's
``<chefbot_sim>`` drive block in the URDF.
"""
from __future__ import annotations

import math
import re
from pathlib import Path

import pytest
import yaml

from chefbot_description.model import expand_xacro, load_sim_params, parse_urdf, wheel_geometry
from chefbot_firmware import virtual_board

ROOT = Path(__file__).resolve().parents[2]
MOTOR_COUNTS_PER_REV_4X = 64       # Pololu 37D encoder, counts per motor-shaft turn, both edges of A and B
GEAR_RATIO = 131.25                # 37Dx73L gearbox
FREE_SPEED_RPM = 80.0              # wheel shaft, 12 V, no load
DECODING = {"X4": 4, "X2": 2, "X1": 1}


@pytest.fixture(scope="module")
def urdf() -> str:
    return expand_xacro()


@pytest.fixture(scope="module")
def diff_drive() -> dict:
    return yaml.safe_load((ROOT / "chefbot_bringup" / "param" / "diff_drive.yaml").read_text())


def firmware_decoding() -> int:
    """Counts per quadrature cycle of the firmware's default encoder mode (config.h)."""
    text = (ROOT / "firmware" / "core" / "config.h").read_text()
    m = re.search(r"EncoderMode\s+encoder_mode\s*=\s*EncoderMode::(X[124])\s*;", text)
    assert m, "firmware/core/config.h: default encoder_mode not found"
    return DECODING[m.group(1)]


def counts_per_wheel_rev() -> float:
    return MOTOR_COUNTS_PER_REV_4X * GEAR_RATIO * firmware_decoding() / 4


def test_urdf_geometry_matches_the_sim_drive_block(urdf: str) -> None:
    geo = wheel_geometry(parse_urdf(urdf))
    drive = load_sim_params(urdf).drive
    assert geo.radius == pytest.approx(drive.wheel_radius, abs=1e-9)
    assert geo.separation == pytest.approx(drive.wheel_separation, abs=1e-9)


def test_diff_drive_yaml_matches_urdf_and_encoder(urdf: str, diff_drive: dict) -> None:
    geo = wheel_geometry(parse_urdf(urdf))
    ticks_meter = counts_per_wheel_rev() / (2 * math.pi * geo.radius)
    # the YAML holds a whole number of ticks per metre (29708: truncated from 29708.9, 0.003 % off)
    assert abs(diff_drive["ticks_meter"] - ticks_meter) < 1.0, f"ticks_meter should be {ticks_meter:.1f}"
    assert diff_drive["base_width"] == pytest.approx(geo.separation, abs=1e-9)
    wheel_speed = FREE_SPEED_RPM / 60 * 2 * math.pi * geo.radius
    assert diff_drive["max_wheel_speed"] == pytest.approx(wheel_speed, abs=5e-4)


def test_board_emulator_matches_encoder_and_motor() -> None:
    assert virtual_board.EDGES_PER_REV == counts_per_wheel_rev()
    assert virtual_board.FREE_SPEED_RAD_S == pytest.approx(FREE_SPEED_RPM / 60 * 2 * math.pi)


def test_firmware_comment_states_the_same_counts() -> None:
    """config.h documents the counts per wheel revolution of each mode: they must be these."""
    text = (ROOT / "firmware" / "core" / "config.h").read_text()
    for mode, factor in DECODING.items():
        m = re.search(rf"{mode} = {factor},\s*//.*?(\d+) counts per (?:wheel )?revolution", text)
        assert m, f"config.h: no counts-per-revolution comment for {mode}"
        assert int(m.group(1)) == MOTOR_COUNTS_PER_REV_4X * GEAR_RATIO * factor / 4, mode


def firmware_inversions() -> dict[str, bool]:
    """The default ``invert_*`` flags of config.h (which motor and encoder are mounted mirrored)."""
    text = (ROOT / "firmware" / "core" / "config.h").read_text()
    flags = dict(re.findall(r"bool\s+(invert_\w+)\s*=\s*(true|false)\s*;", text))
    assert flags, "firmware/core/config.h: no invert_* defaults found"
    return {k: v == "true" for k, v in flags.items()}


def test_bringup_check_and_emulator_expect_this_robot(urdf: str, diff_drive: dict) -> None:
    """The bring-up diagnosis's expectations and the emulator's mounting copy diff_drive.yaml, the
    URDF and config.h (neither may import the other: the diagnosis runs on the real robot)."""
    from chefbot_bringup import bringup_check

    geo = wheel_geometry(parse_urdf(urdf))
    assert bringup_check.TICKS_METER == diff_drive["ticks_meter"]
    assert bringup_check.MAX_WHEEL_SPEED == diff_drive["max_wheel_speed"]
    assert bringup_check.WHEEL_DIAMETER == pytest.approx(2 * geo.radius, abs=1e-9)
    assert virtual_board.WHEEL_RADIUS == pytest.approx(geo.radius, abs=1e-9)
    assert bringup_check.COUNTS_PER_REV_1X * firmware_decoding() == counts_per_wheel_rev()
    assert bringup_check.INVERT_DEFAULTS == firmware_inversions()
    assert virtual_board.MOUNT_DEFAULTS == firmware_inversions()
