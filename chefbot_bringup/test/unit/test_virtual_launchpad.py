"""virtual_launchpad's wrongly built robot (issue 31): ``--fault NAME`` and ``--wheel-scale LEFT RIGHT``.

The parsing is pure (``BuildFaults.from_names`` and the script's ``parse_args``, imported without
running it); one test per direction starts the real script on a pty and drives it as the driver would.
"""
from __future__ import annotations

import importlib.machinery
import importlib.util
import math
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
import serial

import chefbot_bringup
import chefbot_firmware
from chefbot_bringup.launchpad_protocol import Encoders, LineError, parse_line
from chefbot_firmware.virtual_board import FAULT_NAMES, BuildFaults

SCRIPT = Path(__file__).resolve().parents[2] / "nodes" / "virtual_launchpad"
HANG_GUARD_S = 20.0   # against hangs only: the script is up in well under a second
EXPECTED_NAMES = ("left_leads_swapped", "right_leads_swapped", "left_encoder_reversed",
                  "right_encoder_reversed", "encoders_swapped", "motors_swapped")


def load_script():
    """The node script as a module (``__name__`` is not ``__main__``: nothing starts)."""
    name = "_chefbot_test_virtual_launchpad"
    loader = importlib.machinery.SourceFileLoader(name, str(SCRIPT))
    module = importlib.util.module_from_spec(importlib.util.spec_from_loader(name, loader))
    loader.exec_module(module)
    return module


@pytest.fixture(scope="module")
def node():
    return load_script()


# --- BuildFaults.from_names ---------------------------------------------------------------------

def test_fault_names_are_the_bool_fields() -> None:
    assert FAULT_NAMES == EXPECTED_NAMES


def test_no_names_is_a_correctly_built_robot() -> None:
    assert BuildFaults.from_names([]) == BuildFaults()
    assert BuildFaults.from_names([], None) == BuildFaults()
    assert BuildFaults().describe() == "none (a correctly built robot)"


@pytest.mark.parametrize("name", EXPECTED_NAMES)
def test_each_name_sets_only_its_field(name: str) -> None:
    faults = BuildFaults.from_names([name])
    assert faults == BuildFaults(**{name: True})
    assert faults.describe() == name


def test_names_combine_and_repeats_are_harmless() -> None:
    faults = BuildFaults.from_names(["motors_swapped", "left_leads_swapped", "motors_swapped"], (1.03, 0.99))
    assert faults == BuildFaults(motors_swapped=True, left_leads_swapped=True,
                                 left_wheel_scale=1.03, right_wheel_scale=0.99)
    assert faults.describe() == "left_leads_swapped, motors_swapped, wheel scale left 1.03 right 0.99"


def test_unknown_name_lists_the_valid_ones() -> None:
    with pytest.raises(ValueError, match="unknown build fault 'left_lead_swapped'") as err:
        BuildFaults.from_names(["left_leads_swapped", "left_lead_swapped"])
    assert all(n in str(err.value) for n in EXPECTED_NAMES)


@pytest.mark.parametrize("scale", [(0.0, 1.0), (1.0, -0.5), (math.nan, 1.0), (1.0, math.inf), (1.0,),
                                   (1.0, 1.0, 1.0)])
def test_bad_wheel_scale_raises(scale) -> None:
    with pytest.raises(ValueError, match="wheel.scale"):
        BuildFaults.from_names([], scale)


# --- the script's command line ------------------------------------------------------------------

def test_command_line_defaults(node) -> None:
    args, faults = node.parse_args(["__name:=virtual_launchpad", "__log:=/tmp/x.log"])
    assert faults == BuildFaults()
    assert (args.link, args.rate, args.sonar_cm) == ("/tmp/chefbot_launchpad", 500.0, 0.0)


def test_command_line_faults_and_wheel_scale(node) -> None:
    _, faults = node.parse_args(["--fault", "left_leads_swapped", "--fault", "encoders_swapped",
                                 "--wheel-scale", "1.03", "0.99", "__name:=lp"])
    assert faults == BuildFaults(left_leads_swapped=True, encoders_swapped=True,
                                 left_wheel_scale=1.03, right_wheel_scale=0.99)


@pytest.mark.parametrize("argv, message", [
    (["--fault", "left_lead_swapped"], "invalid choice: 'left_lead_swapped'"),
    (["--wheel-scale", "0", "1"], "--wheel-scale: BuildFaults.left_wheel_scale must be a finite number > 0"),
    (["--wheel-scale", "1", "-1"], "--wheel-scale: BuildFaults.right_wheel_scale must be a finite number > 0"),
    (["--wheel-scale", "nan", "1"], "--wheel-scale: BuildFaults.left_wheel_scale must be a finite number > 0"),
    (["--wheel-scale", "1.03"], "expected 2 arguments"),
    (["--wheel-scale", "1.03", "x"], "invalid float value: 'x'"),
    (["--faults", "motors_swapped"], "unrecognized arguments: --faults motors_swapped"),
    (["--rate", "0"], "--rate must be > 0"),
])
def test_bad_command_line_is_an_argparse_error(node, capsys, argv, message) -> None:
    with pytest.raises(SystemExit) as ex:
        node.parse_args(argv)
    assert ex.value.code == 2
    err = capsys.readouterr().err
    assert "usage:" in err and message in err, err
    if argv[0] == "--fault":
        assert all(n in err for n in EXPECTED_NAMES), err


# --- the real script on a pty -------------------------------------------------------------------

def _env() -> dict[str, str]:
    """This process's environment with the modules this test imported first on the child's path
    (a worktree's sources, not another checkout's devel space)."""
    paths = [str(Path(m.__file__).resolve().parents[1]) for m in (chefbot_firmware, chefbot_bringup)]
    return dict(os.environ, PYTHONPATH=os.pathsep.join([*paths, os.environ.get("PYTHONPATH", "")]))


def _wait_for(cond, what: str, proc: subprocess.Popen, log: Path) -> None:
    deadline = time.monotonic() + HANG_GUARD_S
    while not cond():
        assert proc.poll() is None, f"virtual_launchpad ended ({proc.returncode}) before {what}:\n{log.read_text()}"
        assert time.monotonic() < deadline, f"no {what} within {HANG_GUARD_S} s:\n{log.read_text()}"
        time.sleep(0.02)


def drive_left_forward(tmp_path: Path, *options: str) -> tuple[list[Encoders], str]:
    """Start the script with ``options``, send ``s 300 0`` at 20 Hz for 1 s; the board's encoder
    lines and the script's output (after SIGINT, which must end it cleanly)."""
    link = tmp_path / "lp"
    log = tmp_path / "virtual_launchpad.log"
    with open(log, "wb") as out:
        proc = subprocess.Popen([sys.executable, str(SCRIPT), "--link", str(link), *options], env=_env(),
                                stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True)
    try:
        _wait_for(lambda: "build faults:" in log.read_text(), "its start message", proc, log)
        assert link.is_symlink()
        encoders, buf = [], b""
        with serial.Serial(str(link), 115200, timeout=0) as ser:
            for _ in range(20):
                ser.write(b"s 300 0\r")
                time.sleep(0.05)
                buf += ser.read(65536)
            *lines, buf = buf.split(b"\n")
        for raw in lines:
            try:
                msg, _ = parse_line(raw)
            except LineError:
                continue          # the empty line before the hello, a line cut by our late open
            if isinstance(msg, Encoders):
                encoders.append(msg)
        proc.send_signal(signal.SIGINT)
        assert proc.wait(timeout=HANG_GUARD_S) == 0, log.read_text()
        assert not link.exists() and not link.is_symlink(), "the script left its link behind"
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    return encoders, log.read_text()


def test_script_with_left_leads_swapped_counts_the_left_wheel_backward(tmp_path: Path) -> None:
    encoders, out = drive_left_forward(tmp_path, "--fault", "left_leads_swapped")
    assert "build faults: left_leads_swapped" in out
    assert len(encoders) > 10, out
    last = encoders[-1]
    # 300/1023 duty for about 1 s turns the wheel ~0.4 rev: thousands of counts, far from noise
    assert last.left < -1000 and last.right == 0, encoders[-5:]


def test_script_without_faults_counts_the_left_wheel_forward(tmp_path: Path) -> None:
    encoders, out = drive_left_forward(tmp_path)
    assert "build faults: none (a correctly built robot)" in out
    assert len(encoders) > 10, out
    last = encoders[-1]
    assert last.left > 1000 and last.right == 0, encoders[-5:]
