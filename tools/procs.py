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


def _interrupt(signum: int, _frame) -> None:
    raise KeyboardInterrupt(f"signal {signum}")


def stop_on_sigterm() -> None:
    """Make SIGTERM (``kill``, a CI job's timeout) behave like Ctrl-C: KeyboardInterrupt unwinds the
    ``with ProcessGroup`` blocks, which stop roscore/roslaunch and their nodes.  Python's default for
    SIGTERM exits at once, without unwinding: the nodes outlived the command (seen with ``make demo``)."""
    signal.signal(signal.SIGTERM, _interrupt)


def free_port() -> int:
    """A TCP port that is free on the loopback interface right now."""
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _proc_table() -> dict[int, tuple[str, int, int, str]]:
    """Every process in /proc: pid -> (state, ppid, pgrp, start time in clock ticks)."""
    table = {}
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            stat = (entry / "stat").read_text()
        except OSError:
            continue
        # fields after the ")" that closes the command name: state ppid pgrp ... (starttime is the 20th)
        rest = stat[stat.rfind(")") + 2:].split()
        if len(rest) > 19:
            table[int(entry.name)] = (rest[0], int(rest[1]), int(rest[2]), rest[19])
    return table


def group_members(pgid: int) -> list[int]:
    """Live (non-zombie) processes of a process group, read from /proc.

    ``killpg(pgid, 0)`` is not enough: it also succeeds for zombies, such as our
    own not-yet-reaped child or orphans waiting for PID 1 to reap them.
    """
    return [pid for pid, (state, _, pgrp, _) in _proc_table().items()
            if pgrp == pgid and state not in ("Z", "X")]


def group_alive(pgid: int) -> bool:
    return bool(group_members(pgid))


def group_tree(pgid: int) -> dict[int, str]:
    """The live members of a process group and all their descendants: pid -> start time.

    roslaunch starts every node (and roscore's rosmaster) in a session of its own
    (``setsid``), so a node is a descendant of the group but not a member; once
    roslaunch has died its nodes are orphans that no group signal reaches.
    """
    table = _proc_table()
    children: dict[int, list[int]] = {}
    for pid, (_, ppid, _, _) in table.items():
        children.setdefault(ppid, []).append(pid)
    todo = [pid for pid, (state, _, pgrp, _) in table.items() if pgrp == pgid and state not in ("Z", "X")]
    tree: dict[int, str] = {}
    while todo:
        pid = todo.pop()
        if pid in tree:
            continue
        tree[pid] = table[pid][3]
        todo.extend(children.get(pid, []))
    return {pid: start for pid, start in tree.items() if table[pid][0] not in ("Z", "X")}


def node_label(argv: list[str], comm: str) -> str:
    """A process's name for accounting: a ROS node's log name as roslaunch gives it (``__log:=.../
    chefbot1-amcl-5.log`` -> ``chefbot1-amcl-5``: its namespace and name), else its command name."""
    for arg in argv:
        if arg.startswith("__log:="):
            return Path(arg.split(":=", 1)[1]).stem
    return comm


def tree_cpu(pgid: int) -> dict[int, tuple[str, float]]:
    """CPU seconds (user + system) so far of every live process of :func:`group_tree`: pid -> (label
    (:func:`node_label`), seconds).  Two calls' difference is what each process spent in between."""
    tick = os.sysconf("SC_CLK_TCK")
    out = {}
    for pid in group_tree(pgid):
        try:
            stat = Path(f"/proc/{pid}/stat").read_text()
            argv = Path(f"/proc/{pid}/cmdline").read_bytes().decode(errors="replace").split("\0")
        except OSError:     # ended in between
            continue
        rest = stat[stat.rfind(")") + 2:].split()      # fields 3 on: utime and stime are fields 14 and 15
        comm = stat[stat.find("(") + 1:stat.rfind(")")]
        out[pid] = (node_label(argv, comm), (int(rest[11]) + int(rest[12])) / tick)
    return out


def _survivors(tracked: dict[int, str]) -> list[int]:
    """The tracked processes still alive (same pid *and* start time: no reused pid)."""
    table = _proc_table()
    return [pid for pid, start in tracked.items()
            if pid in table and table[pid][3] == start and table[pid][0] not in ("Z", "X")]


def kill_group(pgid: int, grace_int: float = 5.0, grace_term: float = 3.0) -> None:
    """Stop a process group and everything it started.

    SIGINT (roslaunch shuts its nodes down), SIGTERM, then SIGKILL to the group;
    the group's descendants are recorded before and while signalling, and any of
    them still alive at the end (a node roslaunch left behind when it was
    killed) gets SIGTERM, then SIGKILL.
    """
    tracked = group_tree(pgid)
    for sig, grace in ((signal.SIGINT, grace_int), (signal.SIGTERM, grace_term), (signal.SIGKILL, 1.0)):
        tracked.update(group_tree(pgid))
        try:
            os.killpg(pgid, sig)
        except ProcessLookupError:
            break
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and group_alive(pgid):
            tracked.update(group_tree(pgid))
            time.sleep(0.05)
        if not group_alive(pgid):
            break
    stop_tracked(tracked, grace_term)


def stop_tracked(tracked: dict[int, str], grace_term: float = 3.0) -> None:
    """SIGTERM, then SIGKILL, to the processes of ``tracked`` (from :func:`group_tree`) still alive:
    the nodes a roslaunch left behind when it was killed, or when it ended before they did."""
    for sig, grace in ((signal.SIGTERM, grace_term), (signal.SIGKILL, 1.0)):
        survivors = _survivors(tracked)
        if not survivors:
            return
        for pid in survivors:
            try:
                os.kill(pid, sig)
            except ProcessLookupError:
                pass
        deadline = time.monotonic() + grace
        while time.monotonic() < deadline and _survivors(tracked):
            time.sleep(0.05)


def run_captured(cmd: list[str], timeout: float, env: dict | None = None) -> subprocess.CompletedProcess:
    """``subprocess.run(cmd, capture_output=True, text=True, timeout=...)`` in a session of its own,
    for a helper that starts ROS itself (a benchmark's ``--measure`` child).

    On a timeout or an interrupt (Ctrl-C; SIGTERM with :func:`stop_on_sigterm`) the child's group
    and everything it started are stopped with :func:`kill_group` -- SIGINT first, so the child
    unwinds its own ``with ProcessGroup`` blocks -- and the exception propagates.  ``subprocess.run``
    would SIGKILL the child alone and leave its roscore running.
    """
    proc = subprocess.Popen(cmd, env=env, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    try:
        out, err = proc.communicate(timeout=timeout)
    except BaseException:
        kill_group(proc.pid)
        try:
            proc.communicate(timeout=5)
        except (subprocess.TimeoutExpired, ValueError, OSError):
            pass
        raise
    return subprocess.CompletedProcess(cmd, proc.returncode, out, err)


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
