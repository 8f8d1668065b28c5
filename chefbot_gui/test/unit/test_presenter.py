"""Unit tests of the delivery presenter: queue order, state transitions, failure paths.

No ROS, no Qt: a fake robot records the goals and a fake clock drives time.
"""
from __future__ import annotations

import math
from pathlib import Path

import pytest

from chefbot_gui.presenter import (
    HOME,
    DeliveryPresenter,
    Destination,
    OrderMode,
    Outcome,
    Phase,
    Pose,
    ViewState,
    fmt_eta,
    fmt_metres,
    make_destinations,
    table_label,
)

POSES = {
    "home": Pose(0.0, 0.0, 0.0),
    "table_1": Pose(2.0, -3.0, 0.0),
    "table_2": Pose(5.0, -3.0, 0.0),
    "table_3": Pose(8.0, -3.0, 0.0),
    "table_4": Pose(2.0, 0.0, 1.0),
    "table_10": Pose(9.0, 9.0, 0.0),
}


class FakeRobot:
    def __init__(self) -> None:
        self.goals: list[tuple[int, str]] = []
        self.cancels = 0

    def send_goal(self, goal_id: int, dest: Destination) -> None:
        self.goals.append((goal_id, dest.key))

    def cancel_goal(self) -> None:
        self.cancels += 1

    @property
    def last(self) -> tuple[int, str]:
        return self.goals[-1]


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


@pytest.fixture
def clock() -> Clock:
    return Clock()


@pytest.fixture
def robot() -> FakeRobot:
    return FakeRobot()


@pytest.fixture
def p(robot: FakeRobot, clock: Clock) -> DeliveryPresenter:
    pres = DeliveryPresenter(POSES, robot, clock, connect_timeout_s=5.0, wait_time_s=20.0, speed_mps=0.25)
    pres.on_server(True)
    return pres


def finish(p: DeliveryPresenter, robot: FakeRobot, outcome: Outcome = Outcome.SUCCEEDED, text: str = "") -> str:
    gid, key = robot.last
    p.on_goal_done(gid, outcome, text)
    return key


def queue(p: DeliveryPresenter, *keys: str) -> None:
    for k in keys:
        p.select(k)
        p.go()


# ---------------------------------------------------------------- tables
def test_tables_sorted_numerically_with_labels() -> None:
    home, tables = make_destinations(POSES)
    assert home.key == HOME
    assert [t.key for t in tables] == ["table_1", "table_2", "table_3", "table_4", "table_10"]
    assert [t.label for t in tables][-1] == "Table 10"
    assert table_label("bar_counter") == "Bar counter"


def test_labels_stay_unique_for_lookalike_keys() -> None:
    poses = {"home": Pose(0, 0), "table_1": Pose(1, 0), "table_01": Pose(2, 0), "Table_2": Pose(3, 0),
             "table 2": Pose(4, 0), "table_2": Pose(5, 0), "Home": Pose(6, 0)}
    _, tables = make_destinations(poses)
    labels = {t.key: t.label for t in tables}
    assert labels["table_1"] == "Table 1" and labels["table_01"] == "Table 01"
    assert labels["table_2"] == "Table 2"
    # "Table_2" and "table 2" would read "Table 2", "Home" like home: the key is added
    assert labels["Table_2"] == "Table 2 (Table_2)" and labels["table 2"] == "Table 2 (table 2)"
    assert labels["Home"] == "Home (Home)"
    assert len({*labels.values(), "Home"}) == len(labels) + 1


def test_any_name_is_a_table_unless_the_file_lists_its_destinations() -> None:
    poses = {"home": Pose(0, 0), "round_1": Pose(1, 0), "bar": Pose(2, 0), "kitchen": Pose(3, 0)}
    _, tables = make_destinations(poses)
    assert {t.key for t in tables} == {"round_1", "bar", "kitchen"}
    _, tables = make_destinations(poses, ["bar", "round_1"])
    assert {t.key for t in tables} == {"round_1", "bar"}
    with pytest.raises(ValueError, match="sofa"):
        make_destinations(poses, ["bar", "sofa"])
    with pytest.raises(ValueError, match="no table"):
        make_destinations(poses, [])


def test_missing_home_or_tables_rejected() -> None:
    with pytest.raises(ValueError, match="home"):
        make_destinations({"table_1": Pose(0, 0)})
    with pytest.raises(ValueError, match="no table"):
        make_destinations({"home": Pose(0, 0)})


def test_shared_tables_file_loads_through_the_sim_loader() -> None:
    from chefbot_common.tables import load_tables
    path = Path(__file__).resolve().parents[3] / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml"
    pres = DeliveryPresenter(load_tables(path), FakeRobot(), Clock())
    assert [t.key for t in pres.tables] == [f"table_{i}" for i in range(1, 10)]


def test_bad_parameters_rejected(robot: FakeRobot, clock: Clock) -> None:
    with pytest.raises(ValueError, match="speed"):
        DeliveryPresenter(POSES, robot, clock, speed_mps=0.0)
    with pytest.raises(ValueError, match="wait"):
        DeliveryPresenter(POSES, robot, clock, wait_time_s=-1)


# ---------------------------------------------------------------- connection
def test_no_master_then_master_then_connecting(robot: FakeRobot, clock: Clock) -> None:
    pres = DeliveryPresenter(POSES, robot, clock, connect_timeout_s=5.0)
    uri = "http://127.0.0.1:1"
    pres.on_master(uri, False)
    pres.select("table_1")
    clock.t += 60.0  # the server time-out does not run while there is no master
    pres.tick()
    st = pres.state()
    assert st.status == f"no ROS master at {uri} — retrying"
    assert not (st.go_enabled or st.home_enabled or st.cancel_enabled or st.served_enabled)
    pres.go()
    assert robot.goals == []
    pres.on_master(uri, True)
    assert pres.state().status == "connecting…"
    clock.t += 5.1
    pres.tick()
    assert pres.state().status == "robot not connected"
    pres.on_server(True)
    assert pres.state().go_enabled


def test_master_lost_while_driving_stops_and_requeues(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_3")
    p.on_master("http://localhost:11311", False)
    st = p.state()
    assert st.status.startswith("no ROS master at http://localhost:11311")
    assert p.queue == ["table_3"] and p.phase == Phase.STOPPED and not st.go_enabled


def test_connecting_then_not_connected_then_ready(robot: FakeRobot, clock: Clock) -> None:
    pres = DeliveryPresenter(POSES, robot, clock, connect_timeout_s=5.0)
    states: list[ViewState] = []
    pres.subscribe(states.append)
    assert states[-1].status == "connecting…"
    assert not (states[-1].go_enabled or states[-1].home_enabled or states[-1].cancel_enabled)
    clock.t += 4.9
    pres.tick()
    assert pres.state().status == "connecting…"
    clock.t += 0.2
    pres.tick()
    st = pres.state()
    assert st.status == "robot not connected"
    pres.select("table_1")
    assert not pres.state().go_enabled and not pres.state().home_enabled
    pres.go()
    assert robot.goals == []
    pres.on_server(True)
    st = pres.state()
    assert st.status == "ready" and st.go_enabled and st.home_enabled and not st.cancel_enabled


def test_go_disabled_without_selection(p: DeliveryPresenter) -> None:
    assert not p.state().go_enabled
    p.select("table_3")
    assert p.state().go_enabled
    with pytest.raises(KeyError):
        p.select("table_99")
    with pytest.raises(KeyError):
        p.select(HOME)


def test_server_lost_while_driving_requeues_and_recovers(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_2", "table_3")
    assert robot.last[1] == "table_2"
    p.on_server(False)
    st = p.state()
    assert st.status == "robot not connected"
    assert st.queue == ("table_2", "table_3")
    assert not (st.go_enabled or st.home_enabled or st.cancel_enabled)
    # a late result of the lost goal changes nothing
    p.on_goal_done(robot.last[0], Outcome.ABORTED, "late")
    assert p.phase == Phase.STOPPED
    p.on_server(True)
    st = p.state()
    assert st.go_enabled and "press Go to continue" in st.hint
    p.select(None)
    p.go()
    assert robot.last[1] == "table_2"


# ---------------------------------------------------------------- a full run
def test_delivery_run_waits_then_continues_then_returns_home(p: DeliveryPresenter, robot: FakeRobot,
                                                            clock: Clock) -> None:
    queue(p, "table_3", "table_1")
    assert [k for _, k in robot.goals] == ["table_3"]
    st = p.state()
    assert st.status == "driving to Table 3" and st.cancel_enabled and st.queue == ("table_1",)
    p.on_robot_pose(Pose(0.0, -3.0))
    assert p.state().status == "driving to Table 3 (8.0 m, ~32 s)"
    assert finish(p, robot) == "table_3"
    st = p.state()
    assert st.status == "arrived at Table 3" and st.served_enabled and "20 s" in st.hint
    clock.t += 19.0
    p.tick()
    assert p.phase == Phase.WAITING
    clock.t += 1.0
    p.tick()
    assert robot.last[1] == "table_1"
    finish(p, robot)
    p.served()  # served before the wait time is up
    assert robot.last[1] == HOME
    assert p.state().status.startswith("returning home")
    assert not p.state().home_enabled  # already going home
    finish(p, robot)
    st = p.state()
    assert st.status == "arrived home — ready" and st.phase == Phase.IDLE and st.current is None
    assert [k for _, k in robot.goals] == ["table_3", "table_1", HOME]


def test_wait_time_zero_waits_for_served_only(p: DeliveryPresenter, robot: FakeRobot, clock: Clock) -> None:
    p.set_wait_time(0)
    queue(p, "table_1")
    finish(p, robot)
    clock.t += 3600
    p.tick()
    assert p.phase == Phase.WAITING and p.state().hint == "press Served when the food is taken"
    p.served()
    assert robot.last[1] == HOME


def test_go_adds_to_queue_without_duplicates(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1", "table_2", "table_2", "table_1")
    assert len(robot.goals) == 1
    assert p.state().queue == ("table_2",)


def test_table_added_while_returning_home_is_started(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1")
    finish(p, robot)
    p.served()
    assert robot.last[1] == HOME
    queue(p, "table_4")
    assert robot.last[1] == "table_4"
    # the preempted home goal's result is ignored
    p.on_goal_done(robot.goals[-2][0], Outcome.PREEMPTED)
    assert p.phase == Phase.DRIVING and p.current == "table_4"


# ---------------------------------------------------------------- queue order
def test_nearest_first_order(p: DeliveryPresenter, robot: FakeRobot) -> None:
    p.set_order_mode(OrderMode.NEAREST)
    p.on_robot_pose(Pose(0.0, 0.0))
    queue(p, "table_10")  # starts at once: the only one queued
    p.on_goal_done(robot.last[0], Outcome.SUCCEEDED)
    queue(p, "table_3", "table_2", "table_1")
    # shown in service order: nearest from table_10's pose, then nearest from there
    assert p.state().queue == ("table_3", "table_2", "table_1")
    p.on_robot_pose(Pose(2.0, -2.0))  # robot pose wins over the last table when known
    p.served()
    assert robot.last[1] == "table_1"


def test_fifo_order_and_remove(p: DeliveryPresenter, robot: FakeRobot) -> None:
    p.on_robot_pose(Pose(0.0, 0.0))
    queue(p, "table_10", "table_3", "table_1", "table_2")
    assert p.state().queue == ("table_3", "table_1", "table_2")
    p.remove(1)
    p.remove(7)  # out of range: ignored
    st = p.state()
    assert st.queue == ("table_3", "table_2") and st.queue_labels == ("Table 3", "Table 2")
    finish(p, robot)
    p.served()
    assert robot.last[1] == "table_3"


def test_home_clears_queue(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1", "table_2")
    p.home_now()
    assert robot.last[1] == HOME and p.state().queue == ()
    assert p.state().status == "returning home"


# ---------------------------------------------------------------- cancel and failures
def test_cancel_while_driving(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1", "table_2")
    p.cancel()
    assert robot.cancels == 1
    st = p.state()
    assert st.status == "cancelling…" and not st.go_enabled and not st.cancel_enabled
    finish(p, robot, Outcome.PREEMPTED)
    st = p.state()
    assert st.status == "cancelled" and st.phase == Phase.STOPPED
    assert st.queue == ("table_2",) and st.go_enabled and not st.cancel_enabled
    p.select(None)
    p.go()
    assert robot.last[1] == "table_2"


def test_cancel_that_arrives_anyway_counts_as_arrived(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1")
    p.cancel()
    finish(p, robot, Outcome.SUCCEEDED)
    assert p.phase == Phase.WAITING


def test_cancel_while_waiting_stops_run(p: DeliveryPresenter, robot: FakeRobot, clock: Clock) -> None:
    queue(p, "table_1", "table_2")
    finish(p, robot)
    p.cancel()
    assert p.phase == Phase.STOPPED and robot.cancels == 0
    clock.t += 100
    p.tick()
    assert len(robot.goals) == 1


def test_abort_shows_server_reason_and_go_retries(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_4", "table_2")
    finish(p, robot, Outcome.ABORTED, "Failed to find a valid plan.")
    st = p.state()
    assert st.status == "failed: Failed to find a valid plan."
    assert st.queue == ("table_4", "table_2") and st.go_enabled and st.home_enabled and st.remove_enabled
    p.remove(0)
    p.select(None)
    p.go()
    assert robot.last[1] == "table_2"


@pytest.mark.parametrize(("outcome", "text"), [(Outcome.ABORTED, "aborted"), (Outcome.REJECTED, "rejected"),
                                               (Outcome.PREEMPTED, "another client")])
def test_failures_without_text_get_a_default_reason(p: DeliveryPresenter, robot: FakeRobot,
                                                    outcome: Outcome, text: str) -> None:
    queue(p, "table_1")
    finish(p, robot, outcome, "  ")
    assert p.state().status.startswith("failed: ") and text in p.state().status


def test_lost_goal_outcome_requeues(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1")
    finish(p, robot, Outcome.LOST)
    assert p.phase == Phase.STOPPED and p.queue == ["table_1"]


def test_stale_results_are_ignored(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1")
    p.on_goal_done(robot.last[0] + 5, Outcome.ABORTED, "not ours")
    assert p.phase == Phase.DRIVING


# ---------------------------------------------------------------- progress, battery, diagnostics
def test_progress_along_plan(p: DeliveryPresenter, robot: FakeRobot) -> None:
    queue(p, "table_1")  # (2, -3)
    p.on_robot_pose(Pose(0.0, 0.0))
    p.on_plan([(0.0, 0.0), (0.0, -3.0), (2.0, -3.0)])
    st = p.state()
    assert st.remaining_m == pytest.approx(5.0) and st.eta_s == pytest.approx(20.0)
    assert st.progress == pytest.approx(0.0) and st.plan
    p.on_robot_pose(Pose(0.0, -2.0))
    st = p.state()
    assert st.remaining_m == pytest.approx(3.0) and st.progress == pytest.approx(0.4)
    assert st.status == "driving to Table 1 (3.0 m, ~12 s)"
    # a plan that ends elsewhere (stale) falls back to the straight line
    p.on_plan([(0.0, -2.0), (7.0, 7.0)])
    assert p.state().remaining_m == pytest.approx(math.hypot(2.0, 1.0))


def test_battery(p: DeliveryPresenter) -> None:
    assert p.state().battery_percent is None and "no data" in p.state().battery_text
    p.on_battery(0.734, 12.1)
    st = p.state()
    assert st.battery_percent == 73 and st.battery_text == "battery 73 % (12.1 V)" and not st.battery_low
    p.on_battery(0.12)
    assert p.state().battery_low
    p.on_battery(math.nan, 11.0)
    assert p.state().battery_percent is None and "unknown" in p.state().battery_text
    p.on_battery(0.5, 0.0, present=False)
    assert "not present" in p.state().battery_text


def test_diagnostics_worst_entry_and_staleness(p: DeliveryPresenter, clock: Clock) -> None:
    p.on_diagnostic("chefbot: launchpad", 0, "connected")
    assert p.state().health_text == "hardware OK"
    p.on_diagnostic("chefbot: motors", 2, "driver fault")
    st = p.state()
    assert st.health_level == 2 and "driver fault" in st.health_text
    clock.t += 10
    p.tick()
    assert p.state().health_level == 3 and "stale" in p.state().health_text


def test_listener_called_only_on_change(p: DeliveryPresenter) -> None:
    states: list[ViewState] = []
    p.subscribe(states.append)
    p.tick()
    p.tick()
    assert len(states) == 1
    p.select("table_1")
    assert len(states) == 2 and states[-1].selected == "table_1"


def test_huge_coordinates_format_short() -> None:
    """A 1e300 table coordinate used to print as a 300-digit number in the status line."""
    assert fmt_metres(3.25) == "3.2" and fmt_metres(1e300) == "1e+300"
    assert fmt_eta(12.4) == "~12 s" and fmt_eta(600) == "~10 min" and fmt_eta(1e300 / 0.3) == "~5.56e+298 min"
    far = dict(POSES, table_9=Pose(1e300, 0.0))
    robot = FakeRobot()
    pres = DeliveryPresenter(far, robot, Clock(), speed_mps=0.3)
    pres.on_server(True)
    pres.on_robot_pose(Pose(0.0, 0.0))
    queue(pres, "table_9")
    st = pres.state()
    assert st.status == "driving to Table 9 (1e+300 m, ~5.56e+298 min)"
