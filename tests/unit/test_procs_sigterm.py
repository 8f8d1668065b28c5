"""tools/procs: what a command started is stopped with it.

* ``stop_on_sigterm``: a command killed with SIGTERM still stops the process groups it started;
* ``run_captured``: a benchmark's ``--measure`` child that started ROS is stopped whole on a timeout
  (subprocess.run would kill the child alone and leave what it started).
"""
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

# a command that starts a group of its own (as roscore) and waits; it prints the group's pid, or
# writes it to a file when its output is captured
SCRIPT = """
import sys, time
sys.path.insert(0, {tools!r})
import procs
if {handler}:
    procs.stop_on_sigterm()
with procs.ProcessGroup(["sleep", "120"]) as child:
    if {pidfile!r}:
        open({pidfile!r}, "w").write(str(child.proc.pid))
    print(child.proc.pid, flush=True)
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _gone(pid: int, wait_s: float) -> bool:
    deadline = time.monotonic() + wait_s
    while _alive(pid) and time.monotonic() < deadline:
        time.sleep(0.05)
    return not _alive(pid)


def _script(tmp_path: Path, handler: bool, pidfile: Path | None = None) -> list[str]:
    script = tmp_path / "cmd.py"
    script.write_text(SCRIPT.format(tools=str(TOOLS), handler=handler, pidfile=str(pidfile) if pidfile else ""))
    return [sys.executable, str(script)]


def _child_after_sigterm(tmp_path: Path, handler: bool, wait_s: float) -> tuple[int, bool]:
    cmd = subprocess.Popen(_script(tmp_path, handler), stdout=subprocess.PIPE, text=True)
    child = int(cmd.stdout.readline())
    assert _alive(child)
    cmd.send_signal(signal.SIGTERM)
    cmd.wait(timeout=30)
    return child, _gone(child, wait_s)


def test_sigterm_stops_the_started_groups(tmp_path: Path) -> None:
    _, gone = _child_after_sigterm(tmp_path, handler=True, wait_s=10.0)
    assert gone


def test_without_the_handler_the_group_outlives_the_command(tmp_path: Path) -> None:
    # what stop_on_sigterm is for (Python's default SIGTERM action does not unwind)
    child, gone = _child_after_sigterm(tmp_path, handler=False, wait_s=1.0)
    try:
        assert not gone
    finally:
        os.killpg(child, signal.SIGKILL)


def test_run_captured_gives_output_and_exit_code_as_subprocess_run() -> None:
    out = run_captured([sys.executable, "-c", "import sys; print('out'); print('err', file=sys.stderr); sys.exit(3)"],
                       timeout=30)
    assert (out.returncode, out.stdout, out.stderr) == (3, "out\n", "err\n")


def test_run_captured_timeout_stops_what_the_child_started(tmp_path: Path) -> None:
    pidfile = tmp_path / "grandchild.pid"
    with pytest.raises(subprocess.TimeoutExpired):
        run_captured(_script(tmp_path, True, pidfile), timeout=6)     # ample for the child to write its pid
    assert _gone(int(pidfile.read_text()), 10.0)


def test_subprocess_run_timeout_leaves_it_running(tmp_path: Path) -> None:
    # what run_captured is for: subprocess.run kills the child alone on a timeout
    pidfile = tmp_path / "grandchild.pid"
    with pytest.raises(subprocess.TimeoutExpired):
        subprocess.run(_script(tmp_path, True, pidfile), capture_output=True, text=True, timeout=6,
                       start_new_session=True)
    grandchild = int(pidfile.read_text())
    try:
        assert not _gone(grandchild, 1.0)
    finally:
        os.killpg(grandchild, signal.SIGKILL)
