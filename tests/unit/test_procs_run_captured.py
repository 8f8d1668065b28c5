"""tools/procs.run_captured: a benchmark's ``--measure`` child that started ROS is stopped whole on a
timeout or an interrupt (subprocess.run would kill the child alone and leave what it started)."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

TOOLS = Path(__file__).resolve().parents[2] / "tools"
sys.path.insert(0, str(TOOLS))
from procs import run_captured  # noqa: E402

# a child that starts a group of its own (as roscore) and waits; it writes the group's pid to a file
SCRIPT = """
import sys, time
sys.path.insert(0, {tools!r})
import procs
procs.stop_on_sigterm()
with procs.ProcessGroup(["sleep", "120"]) as child:
    open({pidfile!r}, "w").write(str(child.proc.pid))
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _script(tmp_path: Path) -> tuple[list[str], Path]:
    pidfile = tmp_path / "grandchild.pid"
    script = tmp_path / "measure.py"
    script.write_text(SCRIPT.format(tools=str(TOOLS), pidfile=str(pidfile)))
    return [sys.executable, str(script)], pidfile


def _gone(pid: int, wait_s: float) -> bool:
    deadline = time.monotonic() + wait_s
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not _alive(pid)


def test_output_and_exit_code_as_subprocess_run() -> None:
    out = run_captured([sys.executable, "-c", "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"],
                       timeout=30)
    assert (out.returncode, out.stdout, out.stderr) == (3, "out\n", "err\n")


def test_a_timeout_stops_what_the_child_started(tmp_path: Path) -> None:
    cmd, pidfile = _script(tmp_path)
    with pytest.raises(subprocess.TimeoutExpired):
        run_captured(cmd, timeout=6)     # ample for the child to write its pid
    grandchild = int(pidfile.read_text())
    assert _gone(grandchild, 10.0)


def test_subprocess_run_leaves_it_running(tmp_path: Path) -> None:
    # what run_captured is for: subprocess.run kills the child alone on a timeout
    cmd, pidfile = _script(tmp_path)
    with pytest.raises(subprocess.TimeoutExpired):
        subprocess.run(cmd, capture_output=True, text=True, timeout=6, start_new_session=True)
    grandchild = int(pidfile.read_text())
    try:
        assert not _gone(grandchild, 1.0)
    finally:
        os.killpg(grandchild, signal.SIGKILL)
