"""The fleet demo's stand-in fleet (no ROS, no Qt): the scripted scene, its play, staff commands."""
from __future__ import annotations

import pytest
from conftest import TABLES

from chefbot_common.fleet_file import load_fleet, load_kitchen
from chefbot_common.tables import load_tables
from chefbot_gui.fleet_demo import DemoFleet

FLEET = TABLES.parent / "hotel_fleet.yaml"


def hotel(speed: float = 0.3) -> DemoFleet:
    places = {k: (p.x, p.y) for k, p in load_tables(TABLES).items() if k != "home"}
    k = load_kitchen(FLEET)
    places["kitchen"] = (k.x, k.y)
    robots = {r.name: ((r.parking.x, r.parking.y), (r.charger.x, r.charger.y) if r.charger else None)
              for r in load_fleet(FLEET)}
    return DemoFleet(places, robots, speed)


def states(f: DemoFleet) -> dict[str, str]:
    return {o.id: o.state for o in f.orders}


def test_the_scene_has_every_kind_of_robot_and_order() -> None:
    f = hotel(speed=0.0)
    f.step(0.1)
    assert {r.name: r.state for r in f.robots.values()} == {
        "chefbot1": "delivering", "chefbot2": "to_kitchen", "chefbot3": "charging"}
    assert set(states(f).values()) == {"served", "on_the_way", "cancelled", "assigned", "queued"}
    assert all(f.remaining_path(r) for r in f.robots.values() if r.state != "charging")
    etas = {o.id: o.eta for o in f.orders}
    assert etas["o2"] > 0 and etas["o5"] > etas["o4"] > 0 and etas["o1"] == -1
    before = [(r.x, r.y) for r in f.robots.values()]
    f.step(10.0)
    assert [(r.x, r.y) for r in f.robots.values()] == before      # speed 0: a still picture


def test_the_play_serves_every_order_and_parks() -> None:
    f = hotel(speed=0.5)
    for _ in range(4000):
        f.step(0.25)
    st = states(f)
    assert st["o2"] == st["o4"] == st["o5"] == "served"
    assert {f.robots[n].state for n in ("chefbot1", "chefbot2")} == {"idle"}


def test_staff_commands() -> None:
    f = hotel()
    o = f.add_order(["table_8"], robot="chefbot1")
    assert (o.state, o.assigned) == ("assigned", "chefbot1") and "table_8" in f.robots["chefbot1"].stops
    assert f.command("chefbot1", "pause") == "chefbot1 paused"
    assert f.robots["chefbot1"].state == "paused"
    assert (f.order(o.id).state, f.order(o.id).assigned) == ("queued", "")   # only chefbot1 may serve it
    assert f.order("o2").assigned == "chefbot2"                             # the other goes to the other robot
    f.command("chefbot1", "resume")
    assert f.order(o.id).assigned == "chefbot1"
    assert f.cancel(o.id) == f"cancelled {o.id}" and f.order(o.id).state == "cancelled"
    assert f.command("chefbot2", "charge") == "chefbot2 goes to its charger"
    for bad in (lambda: f.add_order(["table_42"]), lambda: f.add_order(["table_1", "table_1"]),
                lambda: f.add_order(["table_1"], robot="ghost"), lambda: f.cancel("o1"),
                lambda: f.cancel("o999"), lambda: f.command("chefbot1", "reboot")):
        with pytest.raises(ValueError):
            bad()
