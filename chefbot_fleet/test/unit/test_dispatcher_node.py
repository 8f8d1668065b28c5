"""The dispatcher node's lock order with actionlib (no ROS master: the node's class, not its process).

actionlib calls a Deliver goal's callback holding the action server's lock, and the dispatcher's loop
answers goals (set_succeeded, feedback: the server's lock) while it holds its own lock; a callback that
took the dispatcher's lock could wait for a loop that waits for the callback's server lock.
"""
from __future__ import annotations

import importlib.machinery
import importlib.util
import queue
import sys
import threading
from pathlib import Path

NODE = Path(__file__).resolve().parents[2] / "nodes" / "dispatcher"


def load_node():
    loader = importlib.machinery.SourceFileLoader("chefbot_dispatcher_node", str(NODE))
    spec = importlib.util.spec_from_loader(loader.name, loader)
    mod = importlib.util.module_from_spec(spec)
    sys.modules[loader.name] = mod                  # its dataclasses look their module up
    loader.exec_module(mod)
    return mod


class Handle:
    """A stand-in for actionlib's ServerGoalHandle: remembers what the dispatcher answered."""

    def __init__(self) -> None:
        self.calls: list[str] = []


def test_the_action_callbacks_do_not_wait_for_the_dispatchers_lock() -> None:
    mod = load_node()
    node = object.__new__(mod.DispatcherNode)       # the class alone: no publishers, no master
    node.lock = threading.RLock()
    node.incoming = queue.Queue()
    held, release = threading.Event(), threading.Event()

    def loop_holding_the_lock() -> None:            # the dispatcher's loop, answering goals
        with node.lock:
            held.set()
            release.wait(10.0)

    loop = threading.Thread(target=loop_holding_the_lock, daemon=True)
    loop.start()
    assert held.wait(5.0)
    goal, cancel = Handle(), Handle()
    callbacks = threading.Thread(target=lambda: (node.on_goal(goal), node.on_goal_cancel(cancel)), daemon=True)
    callbacks.start()
    callbacks.join(5.0)                             # actionlib's thread, holding the server's lock
    alive = callbacks.is_alive()
    release.set()
    loop.join(5.0)
    assert not alive, "a Deliver callback waited for the dispatcher's lock (deadlock with the loop)"
    queued = [node.incoming.get_nowait() for _ in range(node.incoming.qsize())]
    assert [gh for _, gh in queued] == [goal, cancel]
    assert [handle.__func__ for handle, _ in queued] == [mod.DispatcherNode._goal, mod.DispatcherNode._goal_cancel]
