"""Several hosts on one machine: Linux network namespaces on one virtual bridge (pure: no rospy).

A ``VirtualLan`` makes one network namespace per host, each with its own ``eth0`` and address on a
private /24, all plugged into a bridge that lives in a namespace of its own (the machine's own
network is never touched), and takes it all down again.  Tests use it to run a ROS master and nodes
on hosts that reach each other only through the "network", as a restaurant's server and robot PCs
do: a node that binds loopback, advertises ``localhost`` or reads a file only another host has
fails there as it would on the real fleet.

Needs root (CAP_NET_ADMIN and CAP_SYS_ADMIN) and ``ip`` from iproute2; ``unavailable()`` says why
not.  We wrote this ourselves: it is a few ``ip`` commands, and no packaged library drives
namespaces for tests (pyroute2 could, at the cost of a dependency that only this would use).
"""
from __future__ import annotations

import ctypes
import ipaddress
import os
import re
import secrets
import shutil
import signal
import subprocess
import time
from collections.abc import Sequence

CLONE_NEWNET = 0x40000000          # setns(2): join a network namespace
NETNS_DIR = "/run/netns"           # where `ip netns add` keeps its namespaces
_HOST = re.compile(r"[a-z][a-z0-9_]*\Z")


class NetnsError(RuntimeError):
    """A namespace, link or address could not be made (the failing ``ip`` command and its message)."""


def unavailable() -> str:
    """Why a ``VirtualLan`` cannot be made here ("" when it can): not root, no ``ip``, or the kernel
    refuses network namespaces (a container without CAP_SYS_ADMIN)."""
    if os.geteuid() != 0:
        return "network namespaces need root"
    if shutil.which("ip") is None:
        return "no 'ip' command (Debian package iproute2)"
    name = f"cbprobe{secrets.token_hex(3)}"
    made = subprocess.run(["ip", "netns", "add", name], capture_output=True, text=True)
    if made.returncode != 0:
        return f"'ip netns add' refused: {made.stderr.strip()}"
    subprocess.run(["ip", "netns", "del", name], capture_output=True)
    return ""


def _ip(*args: str) -> None:
    done = subprocess.run(["ip", *args], capture_output=True, text=True)
    if done.returncode != 0:
        raise NetnsError(f"ip {' '.join(args)}: {done.stderr.strip() or f'exit {done.returncode}'}")


class VirtualLan:
    """Hosts in network namespaces on one bridge, each at its own address of ``subnet``.

    ``hosts`` are short names (letter, then letters, digits, ``_``); host *i* gets the subnet's
    address *i* + 1.  Namespace names carry a random token, so several LANs (parallel test runs)
    never meet.  Use as a context manager, or ``up()`` then ``down()``.
    """

    def __init__(self, hosts: Sequence[str], subnet: str = "10.213.0.0/24") -> None:
        hosts = list(hosts)
        if not hosts:
            raise ValueError("a VirtualLan needs at least one host")
        for h in hosts:
            if not _HOST.match(h):
                raise ValueError(f"host name {h!r}: a lowercase letter, then lowercase letters, digits or _")
        if len(set(hosts)) != len(hosts):
            raise ValueError(f"a host is named twice: {hosts}")
        net = ipaddress.ip_network(subnet)
        if net.num_addresses < len(hosts) + 2:
            raise ValueError(f"subnet {subnet} is too small for {len(hosts)} hosts")
        self.hosts = hosts
        self.prefixlen = net.prefixlen
        self.token = secrets.token_hex(3)
        self._addr = {h: str(net.network_address + i + 1) for i, h in enumerate(hosts)}
        self._switch = f"cb{self.token}-switch"
        self._made: list[str] = []

    # -- names -------------------------------------------------------------------------------
    def namespace(self, host: str) -> str:
        """The network namespace of ``host`` (``ip netns exec`` takes it)."""
        self._check(host)
        return f"cb{self.token}-{host}"

    def address(self, host: str) -> str:
        """``host``'s IPv4 address on the LAN."""
        self._check(host)
        return self._addr[host]

    def command(self, host: str, argv: Sequence[str]) -> list[str]:
        """``argv`` run on ``host``: ``ip netns exec`` execs it there (same process, other network)."""
        return ["ip", "netns", "exec", self.namespace(host), *argv]

    def _check(self, host: str) -> None:
        if host not in self._addr:
            raise KeyError(f"no host {host!r} on this LAN (hosts: {', '.join(self.hosts)})")

    # -- life --------------------------------------------------------------------------------
    def up(self) -> VirtualLan:
        """Make the bridge and every host (``eth0`` at its address, ``lo`` up); on any failure what
        was made is taken down again and ``NetnsError`` raised."""
        try:
            _ip("netns", "add", self._switch)
            self._made.append(self._switch)
            _ip("-n", self._switch, "link", "add", "br0", "type", "bridge")
            _ip("-n", self._switch, "link", "set", "br0", "up")
            for i, host in enumerate(self.hosts):
                ns = self.namespace(host)
                _ip("netns", "add", ns)
                self._made.append(ns)
                port, peer = f"port{i}", f"eth{i}{self.token}"[:15]
                _ip("-n", self._switch, "link", "add", port, "type", "veth", "peer", "name", peer, "netns", ns)
                _ip("-n", self._switch, "link", "set", port, "master", "br0")
                _ip("-n", self._switch, "link", "set", port, "up")
                _ip("-n", ns, "link", "set", peer, "name", "eth0")
                _ip("-n", ns, "addr", "add", f"{self._addr[host]}/{self.prefixlen}", "dev", "eth0")
                _ip("-n", ns, "link", "set", "eth0", "up")
                _ip("-n", ns, "link", "set", "lo", "up")
        except Exception:
            self.down()
            raise
        return self

    def pids(self, host: str) -> list[int]:
        """Every process whose network is ``host``'s (what ``down`` ends)."""
        ns = self.namespace(host)
        done = subprocess.run(["ip", "netns", "pids", ns], capture_output=True, text=True)
        return [int(p) for p in done.stdout.split()] if done.returncode == 0 else []

    def stop_processes(self, grace: float = 10.0) -> list[int]:
        """SIGTERM every process left on any host but this one (which may have ``enter``-ed a host),
        SIGKILL what is still there after ``grace`` s; returns the pids that had to be signalled."""
        left = [p for h in self.hosts if self.namespace(h) in self._made for p in self.pids(h) if p != os.getpid()]
        if left:
            for sig, wait in ((signal.SIGTERM, grace), (signal.SIGKILL, 5.0)):
                for p in left:
                    try:
                        os.kill(p, sig)
                    except ProcessLookupError:
                        pass
                deadline = time.monotonic() + wait
                while time.monotonic() < deadline and any(_alive(p) for p in left):
                    time.sleep(0.1)
        return left

    def down(self) -> None:
        """End every process still on a host and delete the namespaces (and with them the links)."""
        self.stop_processes()
        for ns in reversed(self._made):
            subprocess.run(["ip", "netns", "del", ns], capture_output=True)
        self._made.clear()

    def __enter__(self) -> VirtualLan:
        return self.up()

    def __exit__(self, *exc: object) -> None:
        self.down()

    # -- this process ------------------------------------------------------------------------
    def enter(self, host: str) -> None:
        """Move the calling thread onto ``host``'s network (setns(2)); threads it starts afterwards
        inherit it.  Call it before the process opens sockets or starts threads (before
        ``rospy.init_node``), so that the whole process is a program on that host."""
        fd = os.open(os.path.join(NETNS_DIR, self.namespace(host)), os.O_RDONLY)
        try:
            if hasattr(os, "setns"):                        # Python 3.12
                os.setns(fd, CLONE_NEWNET)
            else:
                libc = ctypes.CDLL(None, use_errno=True)
                if libc.setns(fd, CLONE_NEWNET) != 0:
                    err = ctypes.get_errno()
                    raise OSError(err, f"setns into {self.namespace(host)}: {os.strerror(err)}")
        finally:
            os.close(fd)


def _alive(pid: int) -> bool:
    """Running (a zombie, ended but not yet reaped by its parent, is not)."""
    try:
        with open(f"/proc/{pid}/stat") as f:
            stat = f.read()
    except OSError:
        return False
    return stat[stat.rfind(")") + 2:][:1] != "Z"
