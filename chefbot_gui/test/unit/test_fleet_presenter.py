"""The fleet presenter without Qt or ROS: rows, colours, stale robots, commands and their replies."""
from __future__ import annotations

import math

import pytest
from conftest import TABLES

from chefbot_common.tables import load_tables
from chefbot_gui.fleet_presenter import (
    PALETTE,
    UNKNOWN_COLOUR,
    DispatchRobot,
    FleetPresenter,
    OrderInfo,
    QueueSnapshot,
    RobotReport,
    battery_view,
    footprint_in_map,
)

POSES = load_tables(TABLES)


class Clock:
    def __init__(self) -> None:
        self.t = 100.0

    def __call__(self) -> float:
        return self.t


class FakePort:
    """Records the presenter's calls at the ROS boundary."""

    def __init__(self) -> None:
        self.calls: list[tuple] = []

    def send_order(self, request, tables, priority, robot) -> None:
        self.calls.append(("order", request, list(tables), priority, robot))

    def cancel_order(self, request, order_id) -> None:
        self.calls.append(("cancel", request, order_id))

    def set_robot(self, request, robot, command) -> None:
        self.calls.append(("robot", request, robot, command))


def make(**kw) -> tuple[FleetPresenter, FakePort, Clock]:
    port, clock = FakePort(), Clock()
    p = FleetPresenter(POSES, port, clock, **kw)
    return p, port, clock


def online(p: FleetPresenter) -> None:
    p.on_dispatcher(True, True)


QUEUE = QueueSnapshot(
    orders=(
        OrderInfo("o1", ("table_3",), "served"),
        OrderInfo("o2", ("table_2", "table_5"), "on_the_way", assigned="chefbot1", eta=95.0),
        OrderInfo("o3", ("table_7",), "assigned", assigned="chefbot2", eta=40.2),
        OrderInfo("o4", ("table_9",), "queued", reason="chefbot2 went offline"),
        OrderInfo("o5", ("table_1",), "cancelled", reason="cancelled by staff"),
    ),
    robots=(
        DispatchRobot("chefbot1", "delivering", "table_2", ("table_2", "table_5"), ("o2",), battery=0.81),
        DispatchRobot("chefbot2", "to_kitchen", "kitchen", ("table_7",), ("o3",), battery=0.15),
        DispatchRobot("chefbot3", "paused", reason="paused by staff"),
    ),
)
CHARGING = DispatchRobot("chefbot3", "charging", "charger:chefbot3", reason="battery 18 %", battery=0.18)


def test_starts_connecting_then_no_dispatcher_after_the_timeout() -> None:
    p, port, clock = make(connect_timeout_s=2.0)
    st = p.state()
    assert st.status == "connecting…" and not st.add_enabled
    clock.t += 2.5
    p.tick()
    st = p.state()
    assert st.status == "no dispatcher on /fleet — is dispatcher.launch running?"
    assert st.tone == "bad"
    p.toggle_table("table_2")
    st = p.state()
    assert not (st.add_enabled or st.cancel_enabled or st.pause_enabled or st.resume_enabled or st.charge_enabled)
    p.add_order()
    assert port.calls == []


def test_no_master_text_and_recovery() -> None:
    p, _, clock = make(connect_timeout_s=1.0)
    p.on_master("http://127.0.0.1:1", False)
    clock.t += 5
    p.tick()
    assert p.state().status == "no ROS master at http://127.0.0.1:1 — retrying"
    p.on_master("http://127.0.0.1:1", True)
    assert p.state().status == "connecting…"
    online(p)
    assert p.state().status.startswith("fleet:")


def test_action_without_services_allows_orders_only() -> None:
    p, _, _ = make()
    p.on_dispatcher(True, False)
    p.on_queue(QUEUE)
    p.toggle_table("table_4")
    p.select_order("o3")
    p.select_robot("chefbot1")
    st = p.state()
    assert st.status == "dispatcher on /fleet without its services"
    assert st.add_enabled and not (st.cancel_enabled or st.pause_enabled or st.charge_enabled)


def test_robot_rows_state_battery_trip_and_colours_in_fleet_order() -> None:
    p, _, _ = make(fleet=("chefbot2", "chefbot1", "chefbot3"))
    online(p)
    p.on_queue(QUEUE)
    for name, x in (("chefbot1", 2.0), ("chefbot2", -1.0), ("chefbot3", 0.0)):
        p.on_robot_report(RobotReport(name, x, 1.0, 0.0))
    rows = {r.name: r for r in p.state().robots}
    assert [r.name for r in p.state().robots] == ["chefbot1", "chefbot2", "chefbot3"]   # the queue's order
    assert rows["chefbot2"].colour == PALETTE[0] and rows["chefbot1"].colour == PALETTE[1]
    assert rows["chefbot1"].state_text == "delivering — Table 2"
    assert rows["chefbot1"].trip_text == "Table 2 → Table 5 (o2)"
    assert (rows["chefbot1"].battery_percent, rows["chefbot1"].battery_text) == (81, "81 %")
    assert rows["chefbot2"].state_text == "to the kitchen — Kitchen" and rows["chefbot2"].battery_low
    assert rows["chefbot3"].state_text == "paused (paused by staff)" and rows["chefbot3"].trip_text == "—"
    p.on_queue(QueueSnapshot(QUEUE.orders, (*QUEUE.robots[:2], CHARGING)))
    assert p.state().robots[2].state_text == "charging (battery 18 %)"      # its own charger: no place named
    st = p.state()
    assert st.status == "fleet: 2 of 3 robots in service, 3 open orders" and st.tone == "wait"


def test_order_rows_open_first_then_final_newest_first_with_eta_and_robot_colour() -> None:
    p, _, _ = make(fleet=("chefbot1", "chefbot2"))
    online(p)
    p.on_queue(QUEUE)
    rows = p.state().orders
    assert [r.id for r in rows] == ["o2", "o3", "o4", "o5", "o1"]
    o2 = rows[0]
    assert (o2.tables_text, o2.state_text, o2.robot, o2.eta_text) == ("Table 2, Table 5", "on the way", "chefbot1",
                                                                      "~2 min")
    assert o2.robot_colour == PALETTE[0]
    assert rows[1].eta_text == "~40 s" and rows[1].robot_colour == PALETTE[1]
    assert rows[2].robot == "—" and rows[2].reason == "chefbot2 went offline" and rows[2].eta_text == "—"
    assert rows[3].final and rows[3].eta_text == "—"
    assert p.state().open_tables == ("table_2", "table_5", "table_7", "table_9")


def test_final_rows_are_capped() -> None:
    p, _, _ = make(max_final_rows=1)
    p.on_queue(QUEUE)
    assert [r.id for r in p.state().orders] == ["o2", "o3", "o4", "o5"]


def test_robot_silent_beyond_the_timeout_is_stale_and_its_path_hidden() -> None:
    p, _, clock = make(stale_timeout_s=3.0)
    online(p)
    p.on_queue(QUEUE)
    p.on_robot_report(RobotReport("chefbot1", 1.0, 2.0, 0.0, path=((1.0, 2.0), (3.0, 2.0))))
    p.on_robot_report(RobotReport("chefbot2", 0.0, 0.0, 0.0))
    clock.t += 2.0
    p.on_robot_report(RobotReport("chefbot2", 0.5, 0.0, 0.0))
    r1 = p.state().robots[0]
    assert not r1.stale and r1.path == ((1.0, 2.0), (3.0, 2.0))
    clock.t += 2.0
    p.tick()
    rows = {r.name: r for r in p.state().robots}
    assert rows["chefbot1"].stale and rows["chefbot1"].path == ()
    assert rows["chefbot1"].pose == (1.0, 2.0, 0.0)            # still drawn where it was last seen
    assert rows["chefbot1"].state_text.endswith("— no report for 4 s")
    assert not rows["chefbot2"].stale
    assert rows["chefbot3"].stale and rows["chefbot3"].state_text.endswith("— no position reported")
    assert p.state().hint == "no position from chefbot1, chefbot3"


def test_unknown_robots_on_either_side() -> None:
    p, _, _ = make()
    online(p)
    q = QueueSnapshot(orders=(OrderInfo("o9", ("table_1",), "assigned", assigned="ghost"),),
                      robots=(DispatchRobot("chefbot1", "idle"),))
    p.on_queue(q)
    p.on_robot_report(RobotReport("visitor", 3.0, 3.0, 0.0, text="driving"))
    st = p.state()
    assert [r.name for r in st.robots] == ["chefbot1", "visitor"]
    visitor = st.robots[1]
    assert not visitor.dispatched and visitor.state_text == "not dispatched (driving)"
    assert st.orders[0].robot == "ghost (unknown robot)" and st.orders[0].robot_colour == UNKNOWN_COLOUR
    assert st.robot_choices == ("chefbot1",)
    p.select_robot("visitor")   # not the dispatcher's: no command for it
    st = p.state()
    assert not (st.pause_enabled or st.resume_enabled or st.charge_enabled)


def test_add_order_sends_one_goal_with_tables_priority_and_robot_then_shows_the_replies() -> None:
    p, port, _ = make()
    online(p)
    p.on_queue(QUEUE)
    p.toggle_table("table_5")
    p.toggle_table("table_2")
    p.toggle_table("table_8")
    p.toggle_table("table_8")    # picked twice: out again
    p.set_priority(2.0)
    p.set_robot_choice("chefbot2")
    assert p.state().add_enabled
    p.add_order()
    assert port.calls == [("order", 1, ["table_5", "table_2"], 2.0, "chefbot2")]
    st = p.state()
    assert st.selected_tables == () and not st.add_enabled
    assert st.reply == "order for Table 5, Table 2…" and st.reply_ok is None
    p.on_order_accepted(1, "order o7")
    assert p.state().reply == "order for Table 5, Table 2: accepted as o7" and p.state().reply_ok
    p.on_order_done(1, "o7", "served", "")
    assert p.state().reply == "order o7 served"
    p.toggle_table("table_1")
    p.add_order()
    p.on_order_accepted(2, "order o8 served")     # seen first when already done: no id guessed
    assert p.state().reply == "order for Table 1: accepted"


def test_refused_order_shows_the_dispatchers_reason() -> None:
    p, _, _ = make()
    online(p)
    p.toggle_table("table_1")
    p.add_order()
    p.on_order_refused(1, "unknown table 'table_1'")
    st = p.state()
    assert st.reply == "order for Table 1: refused: unknown table 'table_1'" and st.reply_ok is False


def test_lost_order_and_failed_order_texts() -> None:
    p, _, _ = make()
    online(p)
    p.toggle_table("table_1")
    p.add_order()
    p.on_order_done(1, "", "lost", "")
    assert p.state().reply == "order for Table 1: lost contact with the dispatcher (its database keeps accepted orders)"
    p.toggle_table("table_2")
    p.add_order()
    p.on_order_done(2, "o3", "failed", "no robot could reach table_2")
    assert p.state().reply == "order o3 failed: no robot could reach table_2" and p.state().reply_ok is False


def test_cancel_selected_open_order_only() -> None:
    p, port, _ = make()
    online(p)
    p.on_queue(QUEUE)
    p.select_order("o1")            # served: nothing to cancel
    assert not p.state().cancel_enabled
    p.cancel_order()
    assert port.calls == []
    p.select_order("o3")
    assert p.state().cancel_enabled
    p.cancel_order()
    assert port.calls == [("cancel", 1, "o3")]
    p.on_reply(1, False, "order o3 is already served")
    assert p.state().reply == "cancel o3: order o3 is already served" and p.state().reply_ok is False


def test_selected_order_gone_from_the_queue_is_unselected() -> None:
    p, _, _ = make()
    p.on_queue(QUEUE)
    p.select_order("o3")
    p.on_queue(QueueSnapshot(orders=QUEUE.orders[:2], robots=QUEUE.robots))
    assert p.state().selected_order is None


@pytest.mark.parametrize("robot,pause,resume,charge", [
    ("chefbot1", True, False, True),     # delivering
    ("chefbot3", False, True, True),     # paused
])
def test_robot_buttons_follow_its_state(robot, pause, resume, charge) -> None:
    p, _, _ = make()
    online(p)
    p.on_queue(QUEUE)
    p.select_robot(robot)
    st = p.state()
    assert (st.pause_enabled, st.resume_enabled, st.charge_enabled) == (pause, resume, charge)


def test_robot_commands_reach_the_port_and_the_reply_line() -> None:
    p, port, _ = make()
    online(p)
    p.on_queue(QUEUE)
    p.select_robot("chefbot1")
    p.robot_command("pause")
    p.robot_command("charge")
    p.robot_command("resume")            # chefbot1 delivering: resume is off
    assert port.calls == [("robot", 1, "chefbot1", "pause"), ("robot", 2, "chefbot1", "charge")]
    p.on_reply(2, True, "chefbot1 goes to its charger after its trip")
    assert p.state().reply == "charge chefbot1: chefbot1 goes to its charger after its trip"
    with pytest.raises(ValueError):
        p.robot_command("reboot")


def test_bad_input_is_refused() -> None:
    p, _, _ = make()
    with pytest.raises(KeyError):
        p.toggle_table("table_99")
    with pytest.raises(KeyError):
        p.set_tables(["home"])
    for bad in (0.5, math.nan, math.inf):
        with pytest.raises(ValueError):
            p.set_priority(bad)
    with pytest.raises(ValueError):
        FleetPresenter(POSES, FakePort(), Clock(), stale_timeout_s=0)


def test_listener_called_on_change_only() -> None:
    p, _, _ = make()
    seen = []
    p.subscribe(seen.append)
    p.tick()
    assert len(seen) == 1
    p.toggle_table("table_3")
    assert len(seen) == 2 and seen[-1].selected_tables == ("table_3",)


def test_battery_view_and_footprint() -> None:
    assert battery_view(-1.0) == (None, "?", False)
    assert battery_view(math.nan) == (None, "?", False)
    assert battery_view(0.19) == (19, "19 %", True)
    assert battery_view(1.4) == (100, "100 %", False)
    r = RobotReport("a", 1.0, 2.0, math.pi / 2, footprint=((0.2, 0.0), (0.0, 0.1)))
    got = footprint_in_map(r)
    assert got[0] == pytest.approx((1.0, 2.2)) and got[1] == pytest.approx((0.9, 2.0))
