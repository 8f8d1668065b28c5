"""Process-group helpers shared by the test runner, the demo and the benchmarks.

Everything ROS we start (roscore, roslaunch, rostest) runs in its own session so
that the whole tree of nodes can be stopped with one signal, and nothing
outlives the command that started it.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import time
from pathlib import Path


def free_port() -> int:
    """A TCP port that is free on the loopback interface right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def group_members(pgid: int) -> list[int]:
    """Live (non-zombie) processes of a process group, read from /proc.

    ``killpg(pgid, 0)`` is not enough: it also succeeds for zombies, such as our
    own not-yet-reaped child or orphans waiting for PID 1 to reap them.
    """
    members = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # fields after the ")" that closes the command name: state ppid pgrp ...
        rest = stat[stat.rfind(")") + 2:].split()
        if len(rest) > 2 and int(rest[2]) == pgid and rest[0] not in ("Z", "X"):
            members.append(int(entry.name))
    return members


def group_alive(pgid: int) -> bool:
    return bool(group_members(pgid))


def kill_group(pgid: int, grace_int: float = 5.0, grace_term: float = 3.0) -> None:
    """Stop a process group: SIGINT (roslaunch shuts its nodes down), SIGTERM, then SIGKILL."""
    for sig, grace in ((signal.SIGINT, grace_int), (signal.SIGTERM, grace_term), (signal.SIGKILL, 1.0)):
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            return
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline:
            if not group_alive(pgid):
                return
            time.sleep(0.05)


class ProcessGroup:
    """A command started in its own session, stopped (with all its children) on exit.

    >>> with ProcessGroup(["roslaunch", "-p", "11400", "pkg", "file.launch"], log=Path("x.log")) as p:
    ...     p.poll()
    """

    def __init__(self, cmd: list[str], env: dict | None = None, log: Path | None = None,
                 cwd: Path | None = None) -> None:
        self.cmd = cmd
        self.env = env
        self.log = log
        self.cwd = cwd
        self.proc: subprocess.Popen | None = None
        self._out = None

    def __enter__(self) -> ProcessGroup:
        if self.log is not None:
            self.log.parent.mkdir(parents=True, exist_ok=True)
            self._out = open(self.log, "wb")
        self.proc = subprocess.Popen(self.cmd, env=self.env, cwd=self.cwd, stdin=subprocess.DEVNULL,
                                     stdout=self._out or subprocess.DEVNULL, stderr=subprocess.STDOUT,
                                     start_new_session=True)
        return self

    def poll(self) -> int | None:
        assert self.proc is not None
        return self.proc.poll()

    def stop(self) -> None:
        if self.proc is not None:
            kill_group(self.proc.pid)
            try:
                self.proc.wait(timeout=5)
            except subprocess.TimeoutExpired:
                pass
        if self._out is not None:
            self._out.close()
            self._out = None

    def __exit__(self, *exc) -> None:
        self.stop()
