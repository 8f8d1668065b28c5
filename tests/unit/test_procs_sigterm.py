"""tools/procs.stop_on_sigterm: a command killed with SIGTERM still stops the process groups it started."""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

TOOLS = Path(__file__).resolve().parents[2] / "tools"

SCRIPT = """
import sys, time
sys.path.insert(0, {tools!r})
import procs
if {handler}:
    procs.stop_on_sigterm()
with procs.ProcessGroup(["sleep", "120"]) as child:
    print(child.proc.pid, flush=True)
    time.sleep(120)
"""


def _alive(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def _child_after_sigterm(tmp_path: Path, handler: bool, wait_s: float) -> int:
    script = tmp_path / "cmd.py"
    script.write_text(SCRIPT.format(tools=str(TOOLS), handler=handler))
    cmd = subprocess.Popen([sys.executable, str(script)], stdout=subprocess.PIPE, text=True)
    child = int(cmd.stdout.readline())
    assert _alive(child)
    cmd.send_signal(signal.SIGTERM)
    cmd.wait(timeout=30)
    deadline = time.monotonic() + wait_s
    while _alive(child) and time.monotonic() < deadline:
        time.sleep(0.05)
    return child


def test_sigterm_stops_the_started_groups(tmp_path: Path) -> None:
    child = _child_after_sigterm(tmp_path, handler=True, wait_s=10.0)
    assert not _alive(child)


def test_without_the_handler_the_group_outlives_the_command(tmp_path: Path) -> None:
    # what stop_on_sigterm is for (Python's default SIGTERM action does not unwind)
    child = _child_after_sigterm(tmp_path, handler=False, wait_s=1.0)
    try:
        assert _alive(child)
    finally:
        os.killpg(child, signal.SIGKILL)
