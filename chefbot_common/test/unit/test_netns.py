"""chefbot_common.netns: hosts in network namespaces reach each other through the bridge only."""
from __future__ import annotations

import os
import subprocess
import sys
import time

import pytest

from chefbot_common import netns

REASON = netns.unavailable()
needs_netns = pytest.mark.skipif(bool(REASON), reason=REASON or "network namespaces available")

# a TCP echo server on (address, port): prints "ready", answers one connection with what it got
SERVER = """
import socket, sys
s = socket.socket(); s.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
s.bind((sys.argv[1], int(sys.argv[2]))); s.listen(1); print("ready", flush=True)
c, _ = s.accept(); c.sendall(b"echo:" + c.recv(64)); c.close()
"""
CLIENT = """
import socket, sys
c = socket.create_connection((sys.argv[1], int(sys.argv[2])), timeout=5); c.sendall(b"hi")
print(c.recv(64).decode())
"""


def test_names_and_addresses() -> None:
    lan = netns.VirtualLan(["server", "chefbot1", "chefbot2"], subnet="10.213.5.0/24")
    assert [lan.address(h) for h in lan.hosts] == ["10.213.5.1", "10.213.5.2", "10.213.5.3"]
    assert lan.namespace("chefbot1").endswith("-chefbot1")
    assert lan.command("server", ["true"])[:3] == ["ip", "netns", "exec"]
    with pytest.raises(KeyError, match="no host 'kitchen'"):
        lan.address("kitchen")


@pytest.mark.parametrize("hosts, subnet, message", [
    ([], "10.213.0.0/24", "at least one host"),
    (["a", "a"], "10.213.0.0/24", "named twice"),
    (["Server"], "10.213.0.0/24", "lowercase"),
    (["a", "b", "c"], "10.213.0.0/30", "too small"),
])
def test_bad_lans_are_refused(hosts, subnet, message) -> None:
    with pytest.raises(ValueError, match=message):
        netns.VirtualLan(hosts, subnet=subnet)


@needs_netns
def test_hosts_talk_through_the_bridge_and_nothing_is_left() -> None:
    lan = netns.VirtualLan(["alpha", "beta"], subnet="10.213.6.0/24")
    with lan:
        server = subprocess.Popen(lan.command("alpha", [sys.executable, "-c", SERVER, lan.address("alpha"), "5555"]),
                                  stdout=subprocess.PIPE, text=True)
        assert server.stdout.readline().strip() == "ready"
        got = subprocess.run(lan.command("beta", [sys.executable, "-c", CLIENT, lan.address("alpha"), "5555"]),
                             capture_output=True, text=True, timeout=20)
        assert got.stdout.strip() == "echo:hi", got.stderr
        server.wait(timeout=10)
        # the LAN's addresses are on its hosts only, not on the machine's own network (nothing is
        # sent there to check: a connection from here would go out of the machine's default route)
        own = subprocess.run(["ip", "-o", "addr"], capture_output=True, text=True, check=True).stdout
        assert lan.address("alpha") not in own and lan.address("beta") not in own
        # a process left on a host is ended by down()
        sleeper = subprocess.Popen(lan.command("beta", ["sleep", "600"]))
        time.sleep(0.2)
        assert sleeper.pid in lan.pids("beta")
        names = [lan.namespace(h) for h in lan.hosts]
    assert sleeper.wait(timeout=20) != 0
    listed = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True).stdout
    assert not any(n in listed for n in names)


@needs_netns
def test_enter_moves_this_process_onto_a_host() -> None:
    lan = netns.VirtualLan(["alpha"], subnet="10.213.7.0/24")
    with lan:
        child = os.fork()
        if child == 0:                      # the child joins alpha and binds its address
            try:
                import socket
                lan.enter("alpha")
                s = socket.socket()
                s.bind((lan.address("alpha"), 0))
                os._exit(0)
            except OSError:
                os._exit(1)
        _, status = os.waitpid(child, 0)
        assert os.waitstatus_to_exitcode(status) == 0
    import socket
    with pytest.raises(OSError):           # this process never joined it: the address is not here
        socket.socket().bind(("10.213.7.1", 0))
