"""The zone reservation rule: one holder per zone, FIFO, one zone per robot, no cycle of waits, and a
silent robot losing its zone; a seeded random property test over many request orders."""
from __future__ import annotations

import numpy as np
import pytest

from chefbot_fleet.reservations import ReservationError, ZoneTable


def test_first_come_first_served_and_release_hands_over() -> None:
    t = ZoneTable()
    assert t.request("a", 1, 0.0)
    assert not t.request("b", 1, 0.1) and not t.request("c", 1, 0.2)
    assert t.request("a", 1, 0.3)                   # asking again while holding: still granted
    assert t.waiting() == {"b": 1, "c": 1}
    assert t.wait_edges() == [("b", "a"), ("c", "a")]
    assert t.release("a", 1.0) == 1
    assert not t.request("c", 1, 1.1)               # c came after b
    assert t.request("b", 1, 1.2) and t.held_by("b") == 1
    assert t.release("b", 2.0) == 1 and t.request("c", 1, 2.1)


def test_a_robot_holds_one_zone_at_a_time() -> None:
    t = ZoneTable()
    assert t.request("a", 1, 0.0)
    with pytest.raises(ReservationError, match="a asks for zone 2 while it holds zone 1"):
        t.request("a", 2, 0.1)
    with pytest.raises(ReservationError, match="zone ids"):
        t.request("a", 0, 0.1)


def test_a_new_request_replaces_an_older_wait() -> None:
    t = ZoneTable()
    t.request("a", 1, 0.0)
    t.request("b", 2, 0.0)
    assert not t.request("c", 1, 0.1)
    assert not t.request("c", 2, 0.2)               # c changed its mind: it waits for zone 2 only
    assert t.waiting() == {"c": 2}


def test_a_silent_robot_loses_its_zone_and_its_place() -> None:
    t = ZoneTable(timeout=5.0)
    t.request("a", 1, 0.0)
    t.request("b", 1, 1.0)
    t.request("c", 2, 1.0)
    assert t.expire(4.9) == []
    t.heartbeat("b", 5.0)
    t.heartbeat("c", 5.0)
    assert t.expire(5.1) == [("a", 1)]             # a was last heard of at 0.0
    assert t.request("b", 1, 6.2)
    t.heartbeat("b", 7.0)
    assert t.expire(10.5) == [("c", 2)] and t.held_by("b") == 1   # c: last heard of at 5.0


@pytest.mark.parametrize("seed", range(40))
def test_random_request_orders_never_share_a_zone_never_cycle_and_always_finish(seed: int) -> None:
    """Robots with random routes through zones follow the rule (request the next zone only after
    releasing the last; wait while refused; stay a random while in a zone).  At every step: no zone
    has two holders, no robot waits while holding, the wait-for graph has no cycle; every route ends."""
    rng = np.random.default_rng(seed)
    n_robots, n_zones = int(rng.integers(2, 7)), int(rng.integers(1, 5))
    routes = {f"r{i}": list(rng.integers(1, n_zones + 1, size=int(rng.integers(1, 6)))) for i in range(n_robots)}
    stay = {r: 0 for r in routes}                   # steps left inside the held zone
    t = ZoneTable(timeout=1e9)
    now = 0.0
    for _ in range(5000):
        if not any(routes.values()) and not any(t.held_by(r) for r in routes):
            break
        now += 1.0
        for r in rng.permutation(list(routes)):     # robots act in a random order each step
            held = t.held_by(r)
            if held:
                stay[r] -= 1
                if stay[r] <= 0:
                    t.release(r, now)               # drove out of the zone (into wide space)
                continue
            if routes[r] and t.request(r, int(routes[r][0]), now):
                routes[r].pop(0)
                stay[r] = int(rng.integers(1, 4))
        holders = list(t.holder.values())
        assert len(holders) == len(set(holders))                       # one zone per robot
        assert all(t.holder.get(z) != r for r, z in t.waiting().items())
        assert not set(t.waiting()) & set(holders)                     # no hold-and-wait
        edges = dict(t.wait_edges())
        for start in edges:                                            # no cycle of waits
            seen, cur = set(), start
            while cur in edges:
                assert cur not in seen, f"cycle of waits through {cur}"
                seen.add(cur)
                cur = edges[cur]
    else:
        pytest.fail(f"routes not finished after 5000 steps: {routes}")
    assert not t.holder and not t.waiting()


def test_a_queued_robot_that_stops_asking_does_not_keep_a_free_zone_from_the_others() -> None:
    """A robot queued behind a holder that then stops asking (a new plan, no goal) left every queue only
    on release: once the zone was free, the robot behind it waited for a head that never came."""
    t = ZoneTable(timeout=10.0)
    assert t.request("chefbot1", 1, 0.0)
    assert not t.request("chefbot2", 1, 0.0)          # queued
    t.withdraw("chefbot2")                            # it no longer heads for zone 1
    t.release("chefbot1", 1.0)
    assert t.request("chefbot3", 1, 2.0)              # the free zone goes to whoever asks now
    assert t.waiting() == {}


def test_a_robot_inside_takes_a_free_zone_ahead_of_the_queue_and_a_grant_can_be_revoked() -> None:
    t = ZoneTable()
    assert t.request("a", 1, 0.0)                     # a booked zone 1 from outside ...
    assert t.revoke(1) == "a"                         # ... but b is found inside it
    assert t.holder == {} and list(t.queues[1]) == ["a"]
    assert t.take("b", 1, 0.1)                        # b takes it ahead of a
    assert t.holder == {1: "b"}
    assert not t.request("a", 1, 0.2)                 # a waits, first in the queue
    assert not t.take("c", 1, 0.3)                    # a held zone is not taken
    t.release("b", 0.4)
    assert t.request("a", 1, 0.5)
    assert t.revoke(2) == ""
