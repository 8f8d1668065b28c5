"""The order planner (chefbot_fleet.dispatch): trips, visiting order, insertion, the baseline, the
order-stream simulation.  Places on a line (x in m), 0.5 m/s: travel times are exact."""
from __future__ import annotations

import statistics

import numpy as np
import pytest

from chefbot_fleet.dispatch import (
    DispatchError,
    NearestIdle,
    Order,
    Outage,
    Planner,
    Schedule,
    Site,
    Trip,
    advance,
    best_order,
    completion_times,
    simulate,
    withdraw,
)

X = {"kitchen": 0.0, "t_west": -10.0, "t_near": 5.0, "t_mid": 10.0, "t_far": 20.0, "t_east": 30.0}
SPEED = 0.5


def line_site(load_s: float = 20.0, serve_s: float = 10.0) -> Site:
    return Site("kitchen", lambda a, b: abs(X[a] - X[b]) / SPEED, lambda a, b: abs(X[a] - X[b]), load_s, serve_s)


def test_orders_are_checked() -> None:
    with pytest.raises(DispatchError, match="at least one table"):
        Order("o1", (), 0.0)
    with pytest.raises(DispatchError, match="priority"):
        Order("o1", ("t_mid",), 0.0, priority=0.5)
    with pytest.raises(DispatchError, match="id"):
        Order("", ("t_mid",), 0.0)
    with pytest.raises(DispatchError, match="finite"):
        Order("o1", ("t_mid",), float("nan"))


def test_a_trip_visits_each_table_once_and_comes_back() -> None:
    site = line_site()
    trip = Trip([Order("a", ("t_mid", "t_far"), 0.0), Order("b", ("t_mid",), 0.0)])
    assert trip.tables() == ["t_mid", "t_far"]
    done, back, place = completion_times(site, "kitchen", 100.0, trip, ["t_mid", "t_far"])
    # load 20 s; 20 s to t_mid, serve 10; 20 s on to t_far, serve 10; 40 s back
    assert done == pytest.approx({"b": 150.0, "a": 180.0})
    assert back == pytest.approx(220.0) and place == "kitchen"


def test_the_visiting_order_minimises_the_weighted_waits() -> None:
    site = line_site()
    near_east, far_west = Order("e", ("t_near",), 0.0), Order("w", ("t_west",), 0.0)
    # equal weights: the near table first (it delays the far one less than the other way round)
    assert best_order(site, Trip([far_west, near_east])) == ["t_near", "t_west"]
    # the far table's order weighs 3: served first
    urgent = Order("w", ("t_west",), 0.0, priority=3.0)
    assert best_order(site, Trip([urgent, near_east])) == ["t_west", "t_near"]
    # beyond exact_stops, the greedy order still visits every table once
    many = Trip([Order(f"o{i}", (t,), 0.0) for i, t in enumerate(X) if t != "kitchen"])
    got = best_order(site, many, exact_stops=2)
    assert sorted(got) == sorted(many.tables()) and got[0] == "t_near"


def test_an_idle_robot_sets_off_at_once_and_later_orders_share_the_next_trip() -> None:
    site = line_site()
    planner = Planner(site)
    sch = Schedule("chefbot1", "kitchen", 0.0, capacity=3)
    planner.insert(Order("o1", ("t_far",), 10.0), [sch], 10.0)
    advance(site, sch, 10.0)
    assert sch.current is not None and [o.id for o in sch.current.orders] == ["o1"] and not sch.pending
    assert sch.served["o1"] == pytest.approx(10.0 + 20.0 + 40.0 + 10.0)
    # the robot is away: o2 waits for its next trip, o3 joins that trip (cheaper than a third trip)
    for k, (oid, table) in enumerate((("o2", "t_mid"), ("o3", "t_near"))):
        planner.insert(Order(oid, (table,), 30.0 + k), [sch], 30.0 + k)
        advance(site, sch, 30.0 + k)
    assert len(sch.pending) == 1 and sorted(o.id for o in sch.pending[0].orders) == ["o2", "o3"]
    assert sch.pending[0].stops == ["t_near", "t_mid"]
    # the loaded trip never changes: an order after it set off goes to a later trip
    advance(site, sch, sch.free_at)
    assert sorted(o.id for o in sch.current.orders) == ["o2", "o3"]
    planner.insert(Order("o4", ("t_near",), sch.free_at - 1.0), [sch], sch.free_at - 1.0)
    assert len(sch.current.orders) == 2 and [o.id for o in sch.pending[0].orders] == ["o4"]


def test_capacity_is_never_exceeded() -> None:
    site = line_site()
    planner = Planner(site)
    busy = Schedule("chefbot1", "kitchen", 1000.0, capacity=2)      # away for a long time
    for k in range(5):
        planner.insert(Order(f"o{k}", ("t_near",), float(k)), [busy], float(k))
    assert all(len(t.orders) <= 2 for t in busy.pending)
    assert sum(len(t.orders) for t in busy.pending) == 5


def test_an_order_for_one_robot_goes_to_it_or_is_refused() -> None:
    site = line_site()
    a, b = Schedule("chefbot1", "kitchen", 0.0), Schedule("chefbot2", "kitchen", 500.0)
    assert Planner(site).insert(Order("o1", ("t_mid",), 0.0, robot="chefbot2"), [a, b], 0.0) is b
    assert Planner(site).insert(Order("o2", ("t_mid",), 0.0), [a, b], 0.0) is a     # free first
    for policy in (Planner(site), NearestIdle(site)):
        with pytest.raises(DispatchError, match="chefbot9"):
            policy.insert(Order("o3", ("t_mid",), 0.0, robot="chefbot9"), [a, b], 0.0)


def test_an_urgent_order_may_go_before_the_queue() -> None:
    site = line_site()
    planner = Planner(site)
    sch = Schedule("chefbot1", "kitchen", 300.0, capacity=1)
    planner.insert(Order("slow", ("t_east",), 0.0), [sch], 0.0)
    planner.insert(Order("urgent", ("t_near",), 1.0, priority=10.0), [sch], 1.0)
    assert [t.orders[0].id for t in sch.pending] == ["urgent", "slow"]


def stream(n: int, rate_per_s: float, seed: int) -> list[Order]:
    """n orders of one or two tables, Poisson arrivals."""
    rng = np.random.default_rng(seed)
    tables = [t for t in X if t != "kitchen"]
    t, out = 0.0, []
    for k in range(n):
        t += float(rng.exponential(1.0 / rate_per_s))
        pick = rng.choice(len(tables), size=int(rng.integers(1, 3)), replace=False)
        out.append(Order(f"o{k}", tuple(tables[i] for i in pick), t))
    return out


def test_every_order_is_served_once_and_more_robots_wait_less() -> None:
    site = line_site()
    orders = stream(30, 1 / 45.0, seed=3)
    one = simulate(site, Planner(site), orders, ["chefbot1"])
    three = simulate(site, Planner(site), orders, ["chefbot1", "chefbot2", "chefbot3"])
    for out in (one, three):
        assert set(out.waits) == {o.id for o in orders}
        # no order is served sooner than driving straight to its farthest table and back from the kitchen
        for o in orders:
            fastest = site.load_s + max(abs(X[t]) for t in o.tables) / SPEED + site.serve_s
            assert out.waits[o.id] >= fastest - 1e-6
    assert statistics.mean(three.waits.values()) < 0.6 * statistics.mean(one.waits.values())
    assert three.makespan < one.makespan
    assert one.metres > 0 and one.percentile(95) >= statistics.median(one.waits.values())


def test_the_planner_waits_less_than_the_nearest_idle_baseline_when_busy() -> None:
    site = line_site()
    means = []
    for seed in range(5):
        orders = stream(30, 1 / 45.0, seed)
        ours = simulate(site, Planner(site), orders, ["chefbot1", "chefbot2"])
        base = simulate(site, NearestIdle(site), orders, ["chefbot1", "chefbot2"])
        assert set(base.waits) == set(ours.waits)
        means.append(statistics.mean(ours.waits.values()) / statistics.mean(base.waits.values()))
    assert statistics.mean(means) < 0.9, means


def test_simulate_refuses_what_it_cannot_run() -> None:
    site = line_site()
    with pytest.raises(DispatchError, match="no robots"):
        simulate(site, Planner(site), stream(3, 0.01, 0), [])
    dup = [Order("o1", ("t_mid",), 0.0), Order("o1", ("t_far",), 1.0)]
    with pytest.raises(DispatchError, match="unique"):
        simulate(site, Planner(site), dup, ["chefbot1"])


def test_a_robot_out_of_service_gives_back_what_it_has_not_served() -> None:
    site = line_site()
    planner = Planner(site)
    sch = Schedule("chefbot1", "kitchen", 0.0, capacity=2)
    for oid, table in (("near", "t_near"), ("far", "t_east")):
        planner.insert(Order(oid, (table,), 0.0), [sch], 0.0)
    advance(site, sch, 0.0)
    planner.insert(Order("next", ("t_mid",), 1.0), [sch], 1.0)
    served_near = sch.served["near"]
    assert served_near < sch.served["far"]
    back = withdraw(sch, served_near + 1.0)               # broke down between the two tables
    assert [o.id for o in back] == ["far", "next"]
    assert sch.served == {"near": served_near} and sch.current is None and not sch.pending
    sch.available = False
    other = Schedule("chefbot2", "kitchen", 0.0)
    assert planner.insert(back[0], [sch, other], served_near + 1.0) is other
    with pytest.raises(DispatchError, match="no robot"):
        NearestIdle(site).insert(back[1], [sch], served_near + 1.0)


@pytest.mark.parametrize("seed", range(8))
def test_outages_lose_no_order_and_serve_none_twice(seed: int) -> None:
    """Random breakdowns (one robot, or all at once): every order is served exactly once (simulate
    raises otherwise), by both policies."""
    site = line_site()
    rng = np.random.default_rng(100 + seed)
    orders = stream(25, 1 / 40.0, seed)
    robots = ["chefbot1", "chefbot2", "chefbot3"]
    outages = []
    for _ in range(4):
        t = float(rng.uniform(0.0, orders[-1].created))
        who = robots if rng.random() < 0.25 else [robots[int(rng.integers(3))]]
        outages += [Outage(r, t, t + float(rng.uniform(30.0, 400.0))) for r in who]
    for policy in (Planner(site), NearestIdle(site)):
        out = simulate(site, policy, orders, robots, outages=outages)
        assert set(out.waits) == {o.id for o in orders}
    with pytest.raises(DispatchError, match="bad outage"):
        simulate(site, Planner(site), orders, robots, outages=[Outage("chefbot9", 0.0, 1.0)])
