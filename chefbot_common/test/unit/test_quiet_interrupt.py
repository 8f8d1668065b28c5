"""chefbot_common.quiet_interrupt: a node stopped while it starts exits quietly, other errors do not.

Each case is a child Python process (the module installs a signal handler on import).  Stopping a
node inside ``rospy.init_node`` or inside a call to the master needs a master: node_stop.test.
"""
from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from types import SimpleNamespace

from chefbot_common.quiet_interrupt import _deadlock_free

HEAD = "from chefbot_common import quiet_interrupt\nimport os, signal, sys, time\n"


def child(body: str) -> tuple[int, str]:
    proc = subprocess.run([sys.executable, "-c", HEAD + body], capture_output=True, text=True, timeout=60)
    return proc.returncode, proc.stdout + proc.stderr


def test_sigint_during_imports_exits_1_without_a_traceback() -> None:
    rc, out = child("os.kill(os.getpid(), signal.SIGINT)\ntime.sleep(5)\nimport scipy.spatial\nprint('NOT REACHED')")
    assert (rc, out) == (1, "")


def test_run_exits_with_mains_status() -> None:
    assert child("quiet_interrupt.run(lambda: 3)")[0] == 3
    assert child("quiet_interrupt.run(lambda: None)")[0] == 0


def test_run_restores_pythons_sigint_handler() -> None:
    rc, out = child("def main():\n    print(signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n"
                    "    return 0\nquiet_interrupt.run(main)")
    assert (rc, out.strip()) == (0, "True")


def test_keyboard_interrupt_before_init_node_exits_1_quietly() -> None:
    rc, out = child("def main():\n    os.kill(os.getpid(), signal.SIGINT)\n    time.sleep(5)\n"
                    "quiet_interrupt.run(main)")
    assert (rc, out) == (1, "")


def test_init_error_without_a_stop_keeps_its_traceback() -> None:
    rc, out = child("import rospy\ndef main():\n    raise rospy.ROSInitException('no master')\n"
                    "quiet_interrupt.run(main)")
    assert rc == 1
    assert "Traceback (most recent call last)" in out and "ROSInitException: no master" in out


def test_other_errors_keep_their_traceback() -> None:
    rc, out = child("def main():\n    raise ValueError('bad param')\nquiet_interrupt.run(main)")
    assert rc == 1 and "ValueError: bad param" in out


def test_handler_runs_inline_when_no_master_call_is_in_progress() -> None:
    core = SimpleNamespace(_xmlrpc_cache={"http://m:11311": SimpleNamespace(_lock=threading.Lock())})
    calls = []
    _deadlock_free(lambda sig, frame: calls.append((sig, threading.current_thread().name)), core)(
        signal.SIGINT, None)
    assert calls == [(signal.SIGINT, threading.current_thread().name)]


def test_handler_moves_to_a_thread_while_a_master_call_holds_the_proxy() -> None:
    lock = threading.Lock()
    core = SimpleNamespace(_xmlrpc_cache={"http://m:11311": SimpleNamespace(_lock=lock)})
    calls, done = [], threading.Event()

    def ros_signal(sig, frame) -> None:   # as rospy's: unregisters through the same proxy
        with lock:
            calls.append((sig, threading.current_thread().name))
        done.set()
    with lock:                            # this thread is "inside a call to the master"
        t0 = time.monotonic()
        _deadlock_free(ros_signal, core)(signal.SIGTERM, None)
        assert time.monotonic() - t0 < 1.0 and not calls     # returned at once, did not deadlock
    assert done.wait(5.0)
    assert calls == [(signal.SIGTERM, "rospy-signal-shutdown")]
