"""Nothing listens on the network unless asked.

Starts a small launch (master, rosout, robot_state_publisher in C++ and
joint_state_publisher in Python) through ``tools/with_env.sh`` — the
environment of every make target — and checks with ``ss -ltnp`` that every
listening TCP socket of that process tree is on 127.0.0.0/8 (or ::1).
"""
from __future__ import annotations

import ipaddress
import os
import re
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
import procs  # noqa: E402  (the workspace's process-group helpers)

HANG_GUARD_S = 120.0  # against hangs only
NODES = ("/rosout", "/robot_state_publisher", "/joint_state_publisher")


def _children() -> dict[int, list[int]]:
    kids: dict[int, list[int]] = {}
    for entry in Path("/proc").iterdir():
        if entry.name.isdigit():
            try:
                stat = (entry / "stat").read_text()
            except OSError:
                continue
            ppid = int(stat[stat.rfind(")") + 2:].split()[1])
            kids.setdefault(ppid, []).append(int(entry.name))
    return kids


def process_tree(pid: int) -> set[int]:
    """``pid`` and all its live descendants (roslaunch puts its nodes in their own sessions)."""
    kids, out, todo = _children(), set(), [pid]
    while todo:
        p = todo.pop()
        out.add(p)
        todo.extend(kids.get(p, []))
    return out


def listening(pids: set[int]) -> list[tuple[str, int, str]]:
    """(local address, pid, command) of every listening TCP socket of ``pids``."""
    out = subprocess.run(["ss", "-Hltnp"], capture_output=True, text=True, check=True).stdout
    found = []
    for line in out.splitlines():
        cols = line.split()
        for name, pid in re.findall(r'\("([^"]+)",pid=(\d+),', line):
            if int(pid) in pids:
                found.append((cols[3], int(pid), name))
    return found


def is_loopback(local: str) -> bool:
    host = local.rsplit(":", 1)[0].strip("[]").split("%")[0]
    return host != "*" and ipaddress.ip_address(host).is_loopback


def test_make_environment_is_loopback_only() -> None:
    r = subprocess.run(["bash", str(ROOT / "tools" / "with_env.sh"), "bash", "-c",
                        'echo "$ROS_IP $ROS_HOSTNAME $LD_PRELOAD"'],
                       capture_output=True, text=True, check=True, env=_env_without_overrides())
    ip, host, preload = (r.stdout.split() + ["", "", ""])[:3]
    assert (ip, host) == ("127.0.0.1", "localhost")
    assert preload.endswith("libchefbot_loopback_bind.so") and Path(preload).is_file()


def _env_without_overrides() -> dict[str, str]:
    env = dict(os.environ)
    for k in ("ROS_IP", "ROS_HOSTNAME", "CHEFBOT_ROS_IP", "LD_PRELOAD", "ROS_MASTER_URI"):
        env.pop(k, None)
    return env


@pytest.mark.skipif(shutil.which("ss") is None, reason="ss (iproute2) missing: run make setup")
def test_every_listening_socket_of_a_launch_is_on_loopback(tmp_path: Path) -> None:
    import rosgraph

    port = procs.free_port()
    uri = f"http://127.0.0.1:{port}"
    env = dict(_env_without_overrides(), ROS_MASTER_URI=uri, ROS_HOME=str(tmp_path / "ros_home"))
    cmd = ["bash", str(ROOT / "tools" / "with_env.sh"), "roslaunch", "-p", str(port),
           "chefbot_description", "view_model.launch", "rviz:=false"]
    with procs.ProcessGroup(cmd, env=env, log=tmp_path / "roslaunch.log") as launch:
        master = rosgraph.Master("/loopback_test", master_uri=uri)
        deadline = time.monotonic() + HANG_GUARD_S

        def nodes() -> set[str]:
            try:
                return {n for _topic, ns in master.getSystemState()[0] for n in ns}
            except (rosgraph.MasterError, OSError):
                return set()
        while not set(NODES) <= nodes():
            assert launch.poll() is None, (tmp_path / "roslaunch.log").read_text()[-2000:]
            assert time.monotonic() < deadline, f"nodes up: {sorted(nodes())}"
            time.sleep(0.2)
        pids = process_tree(launch.proc.pid)
        socks = listening(pids)
    names = {name for _a, _p, name in socks}
    # the master, rosout and robot_state_publisher (C++; ss shows 15-character names) have servers
    assert {"rosmaster", "rosout", "robot_state_pub"} <= names, socks
    assert any(str(port) == a.rsplit(":", 1)[1] for a, _p, _n in socks), socks
    exposed = [s for s in socks if not is_loopback(s[0])]
    assert not exposed, f"listening beyond loopback: {exposed}"
