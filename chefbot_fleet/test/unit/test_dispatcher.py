"""The dispatcher's logic (chefbot_fleet.dispatcher) with robots that drive exactly the straight lines the
planner expects (a discrete-time stand-in for move_base): every order served exactly once, the kitchen one
robot's at a time, faults, pauses, silence, cancellations and restarts re-plan without losing an order."""
from __future__ import annotations

import itertools
import math

import pytest

from chefbot_common.geometry import Pose2D
from chefbot_fleet.dispatcher import (
    Config,
    Dispatcher,
    Goto,
    Stop,
    charger_place,
    localization_report,
    parking_place,
)
from chefbot_fleet.order_store import OrderStore
from chefbot_fleet.travel import Places, straight_route

SPEED = 0.5
TABLES = {f"t{i}": Pose2D(2.0 + 2.0 * (i % 3), -2.0 + 2.0 * (i // 3)) for i in range(9)}
ROBOTS = ["r1", "r2"]


def places() -> Places:
    poses = dict(TABLES)
    poses["kitchen"] = Pose2D(-2.0, 0.0)
    for k, r in enumerate(ROBOTS + ["r3"]):
        poses[parking_place(r)] = Pose2D(0.0, -1.0 + k)
        poses[charger_place(r)] = Pose2D(-3.0, -1.0 + k)
    return Places(poses, straight_route(SPEED))


class World:
    """Robots that carry out the dispatcher's Goto at SPEED along straight lines; ``dead`` ones stop
    reporting, ``broken`` ones have every goal aborted."""

    def __init__(self, disp: Dispatcher, robots=ROBOTS, dt: float = 0.5) -> None:
        self.disp, self.t, self.dt = disp, 0.0, dt
        self.pose = {r: disp.places.pose(parking_place(r)) for r in robots}
        self.goal: dict[str, tuple[Pose2D, int] | None] = {r: None for r in robots}
        self.dead: set[str] = set()
        self.broken: set[str] = set()
        self.doubt: dict[str, str] = {}                     # robot -> what its localization says when in doubt
        self.visits: list[tuple[str, str, float]] = []        # (robot, place, t) of every arrival
        self.log: list = []

    def step(self) -> None:
        self.t += self.dt
        for r, p in self.pose.items():
            if r in self.dead:
                continue
            g = self.goal[r]
            if g is not None:
                target, leg = g
                if r in self.broken:
                    self.goal[r] = None
                    self.disp.leg_done(r, leg, False, "blocked", self.t)
                else:
                    d = p.distance(target)
                    step = SPEED * self.dt
                    if d <= step:
                        self.pose[r] = target
                        self.goal[r] = None
                        self.visits.append((r, self._name(target), self.t))
                        self.disp.leg_done(r, leg, True, "", self.t)
                    else:
                        f = step / d
                        self.pose[r] = Pose2D(p.x + f * (target.x - p.x), p.y + f * (target.y - p.y), target.yaw)
            self.disp.heard(r, self.pose[r], self.t)
            self.disp.localization(r, r not in self.doubt, self.doubt.get(r, "localized"), self.t)
        self.disp.tick(self.t)
        for c in self.disp.commands():
            self.log.append((self.t, c))
            if c.robot in self.dead:
                continue
            if isinstance(c, Goto):
                self.goal[c.robot] = (self.disp.places.pose(c.place), c.leg)
            elif isinstance(c, Stop):
                self.goal[c.robot] = None

    def _name(self, pose: Pose2D) -> str:
        for n in [*TABLES, "kitchen"]:
            if self.disp.places.pose(n) == pose:
                return n
        return "?"

    def run_until(self, done, limit_s: float = 3600.0) -> None:
        end = self.t + limit_s
        while not done():
            assert self.t < end, "not done in time"
            self.step()


def make(tmp_path, robots=ROBOTS, **cfg) -> tuple[Dispatcher, World]:
    store = OrderStore(tmp_path / "orders.db")
    disp = Dispatcher(store, places(), "kitchen", list(TABLES), list(robots), 0.0, Config(**cfg),
                      load_s=5.0, serve_s=3.0)
    return disp, World(disp, robots)


def all_final(disp: Dispatcher) -> bool:
    return not disp.store.orders(open_only=True)


def served_once(disp: Dispatcher) -> dict[str, str]:
    """order -> the robot that served it; asserts every order's history reaches 'served' once."""
    out = {}
    for o in disp.store.orders():
        states = [e.state for e in disp.store.history(o.id)]
        assert states.count("served") == 1, (o.id, states)
        out[o.id] = o.assigned
    return out


def test_two_robots_serve_eight_orders_each_exactly_once_one_at_the_kitchen_at_a_time(tmp_path) -> None:
    disp, world = make(tmp_path)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    ids = []
    for k in range(8):
        ids.append(disp.deliver([f"t{(3 * k) % 9}"] + ([f"t{(3 * k + 1) % 9}"] if k % 2 else []),
                                1.0, "", world.t).id)
        for _ in range(6):
            world.step()
    world.run_until(lambda: all_final(disp))
    who = served_once(disp)
    assert set(who) == set(ids) and set(who.values()) == {"r1", "r2"}       # both robots worked
    # at most one robot at the kitchen at any time: loading periods never overlap
    loading = [(e.t, o.id) for o in disp.store.orders() for e in disp.store.history(o.id) if e.state == "loading"]
    assert loading
    kitchen = sorted(t for r, p, t in world.visits if p == "kitchen")
    assert all(b - a >= disp.site.load_s - 1e-9 for a, b in itertools.pairwise(kitchen))
    # every order's table was reached by the robot that served it, before it was called served
    for o in disp.store.orders():
        served_t = [e.t for e in disp.store.history(o.id) if e.state == "served"][0]
        for table in o.tables:
            assert any(r == o.assigned and p == table and t <= served_t + 1e-9 for r, p, t in world.visits)
    # the robots end at their parking poses
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 120)
    for r in ROBOTS:
        assert world.pose[r].distance(disp.places.pose(parking_place(r))) < 1e-9


def test_a_trip_carries_at_most_capacity_orders_and_a_high_priority_order_goes_first(tmp_path) -> None:
    disp, world = make(tmp_path, robots=["r1"], capacity=2)
    world.run_until(lambda: disp.robots["r1"].state == "idle", 60)
    for t in ("t2", "t5", "t8", "t0"):
        disp.deliver([t], 1.0, "", world.t)
    sch = disp.robots["r1"].schedule
    assert all(len(trip.orders) <= 2 for trip in ([sch.current] if sch.current else []) + sch.pending)
    urgent = disp.deliver(["t6"], 5.0, "", world.t).id
    world.run_until(lambda: all_final(disp))
    served = sorted((disp.store.history(o.id)[-1].t, o.id) for o in disp.store.orders())
    order = [oid for _, oid in served]
    assert order.index(urgent) <= 2            # before the last trip, though ordered last
    trips = [len([1 for e in disp.store.history(o.id) if e.state == "loading"]) for o in disp.store.orders()]
    assert trips == [1] * 5


def test_a_robot_that_stops_reporting_mid_trip_gives_its_orders_to_the_other(tmp_path) -> None:
    disp, world = make(tmp_path, stale_s=5.0)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    for t in ("t2", "t5", "t8", "t1"):
        disp.deliver([t], 1.0, "", world.t)
    world.run_until(lambda: any(disp.store.get(o.id).state == "on_the_way" for o in disp.store.orders()))
    carrier = next(o.assigned for o in disp.store.orders() if o.state == "on_the_way")
    world.dead.add(carrier)
    killed_at = world.t
    world.run_until(lambda: disp.robots[carrier].state == "offline", 30)
    assert world.t - killed_at <= 5.0 + 2 * world.dt
    assert "has not reported" in disp.robots[carrier].reason
    world.run_until(lambda: all_final(disp))
    who = served_once(disp)
    other = ({"r1", "r2"} - {carrier}).pop()
    assert list(who.values()).count(other) >= 1
    assert all(o.state == "served" for o in disp.store.orders())
    requeued = [o.id for o in disp.store.orders() if any(e.state == "queued" and "has not reported" in e.reason
                                                          for e in disp.store.history(o.id))]
    assert requeued and all(who[oid] == other for oid in requeued)
    # it comes back: it reports again and takes orders
    world.dead.discard(carrier)
    world.run_until(lambda: disp.robots[carrier].state == "idle", 30)
    disp.set_robot(other, "pause", world.t)
    late = disp.deliver(["t4"], 1.0, "", world.t).id
    world.run_until(lambda: all_final(disp))
    assert disp.store.get(late).assigned == carrier


def test_a_robot_whose_goals_abort_is_retried_then_faulted_and_its_orders_move(tmp_path) -> None:
    disp, world = make(tmp_path, retries=2, retry_wait_s=2.0, recover_s=0.0)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    oid = disp.deliver(["t8"], 1.0, "r1", world.t).id      # asks for r1 ...
    free = disp.deliver(["t2"], 1.0, "", world.t).id
    world.broken.add("r1")
    world.run_until(lambda: disp.robots["r1"].state == "fault", 60)
    assert "failed to reach" in disp.robots["r1"].reason
    aborts = [c for _, c in world.log if isinstance(c, Goto) and c.robot == "r1"]
    assert len(aborts) >= 3                     # the first try and two retries
    world.run_until(lambda: disp.store.get(free).state == "served", 300)
    assert disp.store.get(free).assigned == "r2"
    assert disp.store.get(oid).state == "queued"           # only r1 may serve it: it waits, not lost
    world.broken.clear()
    assert "takes orders again" in disp.set_robot("r1", "resume", world.t)
    world.run_until(lambda: all_final(disp))
    assert disp.store.get(oid).state == "served" and disp.store.get(oid).assigned == "r1"


def test_a_stalled_robot_is_caught_even_when_move_base_says_nothing(tmp_path) -> None:
    disp, world = make(tmp_path, robots=["r1", "r2"], stall_s=10.0, retries=0)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    oid = disp.deliver(["t5"], 1.0, "", world.t).id
    robot = disp.store.get(oid).assigned
    world.step()
    goal = world.goal[robot]
    world.goal[robot] = None               # its goal is lost: it stands, nothing is reported
    assert goal is not None
    world.run_until(lambda: disp.robots[robot].state == "fault", 30)
    assert "has not moved" in disp.robots[robot].reason
    world.run_until(lambda: all_final(disp))
    assert disp.store.get(oid).assigned != robot


def test_pause_cancel_and_charge(tmp_path) -> None:
    disp, world = make(tmp_path)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    disp.set_robot("r2", "pause", world.t)
    assert disp.set_robot("r2", "resume", world.t) == "r2 takes orders again"
    assert disp.robots["r2"].state == "idle"                 # paused where it parks: it stays there
    disp.set_robot("r2", "pause", world.t)
    a = disp.deliver(["t2"], 1.0, "", world.t).id
    b = disp.deliver(["t2", "t7"], 1.0, "", world.t).id
    c = disp.deliver(["t5"], 1.0, "", world.t).id
    assert {disp.store.get(x).assigned for x in (a, b, c)} == {"r1"}
    world.run_until(lambda: disp.store.get(a).state == "on_the_way")
    assert disp.cancel(b, world.t) == f"order {b} cancelled"
    assert "t7" not in disp.robots["r1"].stops and "t2" in disp.robots["r1"].stops    # a still needs t2
    with pytest.raises(ValueError, match="already cancelled"):
        disp.cancel(b, world.t)
    with pytest.raises(KeyError):
        disp.cancel("nope", world.t)
    msg = disp.set_robot("r1", "charge", world.t)
    assert "after its trip" in msg
    world.run_until(lambda: disp.robots["r1"].state == "charging")
    assert world.pose["r1"].distance(disp.places.pose(charger_place("r1"))) < 1e-9
    assert all(disp.store.get(x).state in ("served", "cancelled") for x in (a, b, c))
    assert "t7" not in [p for r, p, _ in world.visits]
    disp.set_robot("r2", "resume", world.t)
    d = disp.deliver(["t0"], 1.0, "", world.t).id
    assert disp.store.get(d).assigned == "r2"
    world.run_until(lambda: all_final(disp))


def test_bad_orders_and_commands_are_refused_with_the_reason(tmp_path) -> None:
    disp, _ = make(tmp_path)
    with pytest.raises(ValueError, match="unknown table"):
        disp.deliver(["t99"], 1.0, "", 0.0)
    with pytest.raises(ValueError, match="listed twice"):
        disp.deliver(["t1", "t1"], 1.0, "", 0.0)
    with pytest.raises(ValueError, match="unknown robot"):
        disp.deliver(["t1"], 1.0, "r9", 0.0)
    with pytest.raises(ValueError, match="priority"):
        disp.deliver(["t1"], -2.0, "", 0.0)
    with pytest.raises(ValueError, match="unknown command"):
        disp.set_robot("r1", "dance", 0.0)
    with pytest.raises(ValueError, match="offline"):
        disp.set_robot("r1", "resume", 0.0)
    assert disp.store.orders() == []            # nothing half-made
    with pytest.raises(ValueError, match="capacity"):
        Config(capacity=0)
    with pytest.raises(KeyError, match="no place"):
        Dispatcher(disp.store, places(), "pantry", list(TABLES), ROBOTS, 0.0)


def test_a_restarted_dispatcher_resumes_the_queue_and_the_plates_on_board(tmp_path) -> None:
    disp, world = make(tmp_path)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    for t in ("t2", "t5", "t8", "t1", "t4", "t7"):
        disp.deliver([t], 1.0, "", world.t)
    world.run_until(lambda: sum(o.state == "served" for o in disp.store.orders()) >= 1)
    before = {o.id: (o.state, o.assigned) for o in disp.store.orders()}
    carried = {k: v for k, v in before.items() if v[0] in ("loading", "on_the_way")}
    assert carried
    disp.store.close()                         # the dispatcher dies; the robots finish their goals and stand
    world.step()

    again = Dispatcher(OrderStore(tmp_path / "orders.db"), places(), "kitchen", list(TABLES), ROBOTS, world.t,
                       Config(), load_s=5.0, serve_s=3.0)
    for oid, (state, robot) in before.items():      # same queue, same assignments
        o = again.store.get(oid)
        assert o.state == ("on_the_way" if state == "loading" else state) and o.assigned == robot
    world.disp = again
    world.goal = {r: None for r in ROBOTS}
    world.run_until(lambda: all_final(again))
    who = served_once(again)
    assert all(who[k] == v[1] for k, v in carried.items())      # the plates on board stayed with their robot


def test_a_robot_silent_after_a_restart_gives_back_its_orders(tmp_path) -> None:
    disp, world = make(tmp_path, stale_s=5.0)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    for t in ("t2", "t5", "t8", "t1"):
        disp.deliver([t], 1.0, "", world.t)
    world.run_until(lambda: any(o.state == "on_the_way" for o in disp.store.orders()))
    carrier = next(o.assigned for o in disp.store.orders() if o.state == "on_the_way")
    disp.store.close()
    again = Dispatcher(OrderStore(tmp_path / "orders.db"), places(), "kitchen", list(TABLES), ROBOTS, world.t,
                       Config(stale_s=5.0), load_s=5.0, serve_s=3.0)
    world.disp, world.goal = again, {r: None for r in ROBOTS}
    world.dead.add(carrier)
    world.run_until(lambda: all_final(again))
    assert all(o.assigned != carrier or o.state != "served" for o in again.store.orders()
               if any(e.state == "queued" and "has not reported" in e.reason for e in again.store.history(o.id)))
    served_once(again)


def test_etas_count_down_and_nearest_idle_is_a_policy(tmp_path) -> None:
    disp, world = make(tmp_path, policy="nearest_idle")
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    oid = disp.deliver(["t8"], 1.0, "", world.t).id
    eta0 = disp.etas(world.t)[oid]
    expect = (disp.site.travel(f"@{disp.store.get(oid).assigned}", "kitchen") + disp.site.load_s
              + disp.site.travel("kitchen", "t8"))
    assert eta0 == pytest.approx(expect, abs=1.0)
    for _ in range(20):
        world.step()
    eta1 = disp.etas(world.t)[oid]
    assert eta1 == pytest.approx(eta0 - 10.0, abs=1.5)      # 10 s later, 10 s nearer
    world.run_until(lambda: all_final(disp))
    assert oid not in disp.etas(world.t)
    assert math.isfinite(eta1)


def test_an_order_made_while_its_robot_drives_to_the_kitchen_joins_the_trip(tmp_path) -> None:
    disp, world = make(tmp_path, robots=["r1"])
    world.run_until(lambda: disp.robots["r1"].state == "idle", 60)
    a = disp.deliver(["t2"], 1.0, "", world.t).id
    world.step()
    assert disp.robots["r1"].state == "to_kitchen"
    b = disp.deliver(["t5"], 1.0, "", world.t).id
    world.run_until(lambda: all_final(disp))
    loaded = {x: [e.t for e in disp.store.history(x) if e.state == "loading"] for x in (a, b)}
    assert loaded[a] == loaded[b] and len(loaded[a]) == 1          # one trip
    world.run_until(lambda: disp.robots["r1"].state == "idle", 120)
    # cancelling the only order of a trip not yet loaded sends the robot back to its parking pose
    c = disp.deliver(["t8"], 1.0, "", world.t).id
    world.step()
    assert disp.robots["r1"].state == "to_kitchen"
    disp.cancel(c, world.t)
    assert disp.robots["r1"].state == "parking"
    cancelled_at = world.t
    world.run_until(lambda: disp.robots["r1"].state == "idle", 60)
    assert not [p for _, p, t in world.visits if t > cancelled_at and p == "kitchen"]
    assert disp.store.get(c).state == "cancelled"


def test_a_robot_in_fault_tries_its_parking_pose_after_recover_s_and_is_back_in_service(tmp_path) -> None:
    disp, world = make(tmp_path, robots=["r1"], retries=1, retry_wait_s=2.0, recover_s=30.0)
    world.run_until(lambda: disp.robots["r1"].state == "idle", 60)
    oid = disp.deliver(["t8"], 1.0, "", world.t).id
    world.broken.add("r1")
    world.run_until(lambda: disp.robots["r1"].state == "fault", 60)
    faulted = world.t
    assert disp.store.get(oid).state == "queued"            # nobody else: it waits, not lost
    world.run_until(lambda: disp.robots["r1"].state != "fault", 60)
    assert world.t - faulted >= 30.0 - 1e-9
    world.run_until(lambda: disp.robots["r1"].state == "fault", 60)   # still broken: in fault again
    world.broken.clear()
    world.run_until(lambda: all_final(disp), 600)                      # the next try works: it serves
    assert disp.store.get(oid).state == "served" and disp.store.get(oid).assigned == "r1"


def test_a_robot_low_on_battery_finishes_its_trip_charges_and_comes_back_by_itself(tmp_path) -> None:
    disp, world = make(tmp_path)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    a = disp.deliver(["t8"], 1.0, "r1", world.t).id
    world.run_until(lambda: disp.store.get(a).state == "on_the_way")
    b = disp.deliver(["t7"], 1.0, "", world.t).id          # r1 would take it after its trip, if it could
    disp.battery("r1", 0.20, world.t)
    assert disp.robots["r1"].reason.startswith("battery 20 %")
    assert disp.store.get(b).assigned == "r2"               # nothing new for r1
    world.run_until(lambda: disp.robots["r1"].state == "charging")
    assert disp.store.get(a).state == "served"              # it finished the trip it was on
    assert world.pose["r1"].distance(disp.places.pose(charger_place("r1"))) < 1e-9
    disp.battery("r1", 0.5, world.t)
    c = disp.deliver(["t1"], 1.0, "", world.t).id
    assert disp.store.get(c).assigned == "r2"               # still charging
    disp.battery("r1", 0.95, world.t)
    assert disp.robots["r1"].state == "parking"             # charged: back in service, on its way to park
    d = disp.deliver(["t0"], 1.0, "r1", world.t).id
    world.run_until(lambda: all_final(disp))
    assert disp.store.get(d).state == "served"
    # nonsense readings are ignored; a paused robot is not sent to charge (staff hold it)
    disp.battery("r2", float("nan"), world.t)
    disp.battery("r2", 7.0, world.t)
    assert disp.robots["r2"].battery != 7.0
    disp.set_robot("r2", "pause", world.t)
    disp.battery("r2", 0.1, world.t)
    assert disp.robots["r2"].state == "paused"
    with pytest.raises(ValueError, match="low_battery"):
        Config(low_battery=0.9, charged_battery=0.5)


def test_a_robot_without_a_charger_is_only_warned_about(tmp_path) -> None:
    poses = {n: places().pose(n) for n in [*TABLES, "kitchen", parking_place("r1")]}
    store = OrderStore(tmp_path / "orders.db")
    disp = Dispatcher(store, Places(poses, straight_route(SPEED)), "kitchen", list(TABLES), ["r1"], 0.0)
    disp.heard("r1", poses[parking_place("r1")], 0.0)
    disp.battery("r1", 0.1, 0.0)
    assert disp.robots["r1"].state == "idle" and "no charger" in disp.robots["r1"].reason
    with pytest.raises(ValueError, match="no charger"):
        disp.set_robot("r1", "charge", 0.0)


def test_a_robot_whose_localization_is_in_doubt_is_lost_stopped_and_back_once_localized(tmp_path) -> None:
    disp, world = make(tmp_path, lost_s=10.0, recover_s=20.0)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    ids = [disp.deliver(t, 1.0, "", world.t).id for t in (["t8", "t2"], ["t5", "t7"])]   # long trips
    world.run_until(lambda: any(disp.store.get(i).state == "on_the_way" for i in ids))
    carrier = next(disp.store.get(i).assigned for i in ids if disp.store.get(i).state == "on_the_way")
    other = ({"r1", "r2"} - {carrier}).pop()
    # a short doubt (a few poor scans) is not lost
    world.doubt[carrier] = "estimate may be wrong: mean beam fit 0.41 < 0.5"
    for _ in range(int(3.0 / world.dt)):
        world.step()
    del world.doubt[carrier]
    world.step()
    assert disp.robots[carrier].state not in ("lost", "fault")
    # a lasting one is: stopped at once, its plates' orders planned onto the other
    world.doubt[carrier] = "not localized: position spread 1.20 m > 0.5 m"
    doubted = world.t
    world.run_until(lambda: disp.robots[carrier].state == "lost", 30)
    logged = len(world.log)
    world.step()
    assert world.t - doubted - world.dt == pytest.approx(10.0, abs=2 * world.dt)
    assert "lost" in disp.robots[carrier].reason and "position spread" in disp.robots[carrier].reason
    assert world.goal[carrier] is None                    # stopped (a Stop if it was driving)
    assert not any(isinstance(c, Goto) and c.robot == carrier for _, c in world.log[logged:])
    lost_at = len(world.log)
    for _ in range(int(60.0 / world.dt)):          # longer than recover_s: a lost robot is sent nowhere
        world.step()
    assert disp.robots[carrier].state == "lost"
    assert not any(isinstance(c, Goto) and c.robot == carrier for _, c in world.log[lost_at:])
    world.run_until(lambda: all_final(disp))
    who = served_once(disp)
    requeued = [i for i in ids if any("is lost" in e.reason for e in disp.store.history(i))]
    assert requeued and all(who[i] == other for i in requeued)
    # localized again (amcl recovered, or staff gave it its pose): to its parking pose, in service
    del world.doubt[carrier]
    world.run_until(lambda: disp.robots[carrier].state == "idle", 60)
    assert world.pose[carrier].distance(disp.places.pose(parking_place(carrier))) < 1e-6
    disp.set_robot(other, "pause", world.t)
    late = disp.deliver(["t4"], 1.0, "", world.t).id
    world.run_until(lambda: all_final(disp))
    assert disp.store.get(late).assigned == carrier


def test_a_robot_in_fault_is_not_sent_to_park_while_its_localization_is_in_doubt(tmp_path) -> None:
    disp, world = make(tmp_path, robots=["r1"], retries=0, recover_s=10.0, lost_s=0.0)   # lost_s 0: never lost
    world.run_until(lambda: disp.robots["r1"].state == "idle", 60)
    disp.deliver(["t8"], 1.0, "", world.t)
    world.broken.add("r1")
    world.run_until(lambda: disp.robots["r1"].state == "fault", 60)
    world.broken.clear()
    world.doubt["r1"] = "no scan for 3.0 s"
    for _ in range(int(40.0 / world.dt)):
        world.step()
    assert disp.robots["r1"].state == "fault"             # never lost (lost_s 0), but not driven either
    del world.doubt["r1"]
    world.run_until(lambda: all_final(disp), 600)


def test_staff_may_resume_a_lost_robot_and_a_paused_one_is_not_made_lost(tmp_path) -> None:
    disp, world = make(tmp_path, robots=["r1", "r2"], lost_s=5.0)
    world.run_until(lambda: all(r.state == "idle" for r in disp.robots.values()), 60)
    disp.set_robot("r2", "pause", world.t)
    world.doubt["r1"] = world.doubt["r2"] = "not localized"
    world.run_until(lambda: disp.robots["r1"].state == "lost", 30)
    assert disp.robots["r2"].state == "paused"
    del world.doubt["r1"]
    disp.robots["r1"].doubt_since = None
    assert "takes orders again" in disp.set_robot("r1", "resume", world.t)
    assert disp.robots["r1"].state in ("idle", "parking")


def test_localization_report_reads_the_localizers_status() -> None:
    statuses = [("/chefbot1/move_base: controller", 0, "ok"),
                ("/chefbot1/amcl: localization", 1, "not localized: position spread 0.9 m")]
    assert localization_report(statuses) == (False, "not localized: position spread 0.9 m")
    assert localization_report([("/chefbot1/amcl: localization", 0, "localized")]) == (True, "localized")
    assert localization_report([("/chefbot1/amcl: localization", 3, "stale")])[0] is False
    assert localization_report([("/chefbot1/move_base: controller", 2, "x")]) is None
    with pytest.raises(ValueError, match="lost_s"):
        Config(lost_s=-1.0)
