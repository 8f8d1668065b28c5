"""Fixtures for the GUI tests that need ROS: a private roscore, one rospy node per
process, a controllable fake ``move_base`` server, and the GUI wired to them.

The pure tests (presenter, geometry) use none of these, so they run without a master.
"""
from __future__ import annotations

import os
import signal
import socket
import subprocess
import threading
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path

import pytest

os.environ.setdefault("QT_QPA_PLATFORM", "offscreen")

PKG = Path(__file__).resolve().parents[2]
TABLES = PKG.parent / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml"
MASTER_TIMEOUT_S = 30.0


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def _kill_group(proc: subprocess.Popen) -> None:
    for sig, grace in ((signal.SIGINT, 5.0), (signal.SIGTERM, 3.0), (signal.SIGKILL, 2.0)):
        try:
            os.killpg(proc.pid, sig)
        except ProcessLookupError:
            break
        try:
            proc.wait(timeout=grace)
        except subprocess.TimeoutExpired:
            continue
        # roscore exited; its children (rosmaster, rosout) share the group: make sure they go too
        try:
            os.killpg(proc.pid, signal.SIGKILL)
        except ProcessLookupError:
            pass
        break


@pytest.fixture(scope="session")
def ros_master() -> Iterator[str]:
    """A roscore on a free port, in its own process group, killed at the end of the session."""
    import rosgraph

    uri = f"http://127.0.0.1:{_free_port()}"
    port = uri.rsplit(":", 1)[1]
    env = dict(os.environ, ROS_MASTER_URI=uri)
    proc = subprocess.Popen(["roscore", "-p", port], env=env, stdin=subprocess.DEVNULL,
                            stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True)
    os.environ["ROS_MASTER_URI"] = uri
    try:
        deadline = time.monotonic() + MASTER_TIMEOUT_S
        while not rosgraph.Master("/chefbot_gui_probe", master_uri=uri).is_online():
            if proc.poll() is not None or time.monotonic() > deadline:
                pytest.fail(f"roscore on {uri} did not come up (exit {proc.poll()})")
            time.sleep(0.1)
        yield uri
    finally:
        _kill_group(proc)


@pytest.fixture(scope="session")
def ros_node(ros_master: str) -> Iterator[None]:
    """rospy.init_node, exactly once per test process (rospy allows no second call)."""
    import rospy

    rospy.init_node("chefbot_gui_test", anonymous=True, disable_signals=True)
    yield
    rospy.signal_shutdown("chefbot_gui tests done")


class FakeMoveBase:
    """A real actionlib ``MoveBaseAction`` server whose behaviour the test sets.

    ``mode``: ``"hold"`` keeps the goal active until cancelled, ``"succeed"``
    and ``"abort"`` (with ``reason``) end it at once.  ``goals`` records every
    goal received, ``cancelled`` is set when a cancel arrives.
    """

    def __init__(self, ns: str, mode: str = "hold", reason: str = "") -> None:
        import actionlib
        from move_base_msgs.msg import MoveBaseAction

        self.ns, self.mode, self.reason = ns, mode, reason
        self.goals: list = []
        self.cancelled = threading.Event()
        self._wake = threading.Event()
        self._stopping = False
        self.server = actionlib.SimpleActionServer(ns, MoveBaseAction, self._execute, auto_start=False)
        self.server.start()

    def set_mode(self, mode: str, reason: str = "") -> None:
        self.mode, self.reason = mode, reason
        self._wake.set()

    def _execute(self, goal) -> None:
        import rospy

        self.goals.append(goal)
        while not rospy.is_shutdown() and not self._stopping:
            if self.server.is_preempt_requested():
                self.cancelled.set()
                self.server.set_preempted(text="cancelled by the client")
                return
            if self.mode == "succeed":
                self.server.set_succeeded(text="arrived")
                return
            if self.mode == "abort":
                self.server.set_aborted(text=self.reason)
                return
            self._wake.wait(0.02)  # server-side poll for preempt/mode; not a test wait
            self._wake.clear()
        self.server.set_aborted(text="server shutting down")

    def stop(self) -> None:
        """Kill the server as a crashing move_base would: topics gone, no result sent."""
        sas = self.server
        asv = sas.action_server
        asv.stop()
        # a crashed server sends nothing more: mute what ending the execute loop would publish
        asv.publish_result = asv.publish_feedback = asv.publish_status = lambda *a, **k: None
        self._stopping = True
        self._wake.set()
        with sas.terminate_mutex:
            sas.need_to_terminate = True
        with sas.execute_condition:
            sas.execute_condition.notify_all()
        sas.execute_thread.join(timeout=5.0)


@pytest.fixture
def fake_servers(ros_node: None) -> Iterator[Callable[..., FakeMoveBase]]:
    """Factory of fake move_base servers, all stopped after the test."""
    made: list[FakeMoveBase] = []

    def make(ns: str, mode: str = "hold", reason: str = "") -> FakeMoveBase:
        s = FakeMoveBase(ns, mode, reason)
        made.append(s)
        return s

    yield make
    for s in made:
        if not s._stopping:
            s.stop()


_counter = iter(range(1, 10_000))


@dataclass
class Gui:
    """One GUI instance under test and the names it uses."""

    ns: str
    window: object
    presenter: object
    bridge: object

    @property
    def action(self) -> str:
        return f"{self.ns}/move_base"


@pytest.fixture
def make_gui(ros_node: None, qtbot) -> Iterator[Callable[..., Gui]]:
    """Factory: a window + presenter + ROS bridge in a fresh namespace (no crosstalk
    between tests in this process); everything shut down after the test."""
    from chefbot_common.tables import load_tables
    from chefbot_gui.app import wire
    from chefbot_gui.presenter import DeliveryPresenter
    from chefbot_gui.ros_bridge import BridgeParams, RosBridge
    from chefbot_gui.window import RobotGuiWindow

    made: list[Gui] = []

    def make(server_timeout: float = 10.0, wait_time: float = 0.0) -> Gui:
        ns = f"/gui_test_{os.getpid()}_{next(_counter)}"
        params = BridgeParams(action=f"{ns}/move_base", map_topic=f"{ns}/map", plan_topic=f"{ns}/plan",
                              amcl_topic=f"{ns}/amcl_pose", battery_topic=f"{ns}/battery_state",
                              diagnostics_topic=f"{ns}/diagnostics", base_frame=f"{ns[1:]}_base_footprint")
        bridge = RosBridge(params)
        presenter = DeliveryPresenter(load_tables(TABLES), bridge, time.monotonic,
                                      connect_timeout_s=server_timeout, wait_time_s=wait_time)
        window = RobotGuiWindow(presenter)
        qtbot.addWidget(window)
        wire(bridge, window)
        bridge.start()
        window.show()
        gui = Gui(ns, window, presenter, bridge)
        made.append(gui)
        return gui

    yield make
    for g in made:
        g.bridge.shutdown()
        g.window.close()
