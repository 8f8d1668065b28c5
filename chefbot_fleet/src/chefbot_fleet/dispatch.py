"""The restaurant's orders planned onto the fleet's trips (pure; times are float seconds, places names).

The model
---------
* An **order** (:class:`Order`) asks for plates at one or more tables.  Its **wait** runs from
  ``created`` until the robot stands at its last table (order -> plate at the table); ``priority``
  (>= 1) weights it.
* A robot serves orders in **trips** (:class:`Trip`): at the kitchen it loads at most ``capacity``
  orders (``load_s``), drives to their tables -- each table once, however many of the trip's orders
  it serves -- stopping ``serve_s`` at each, and comes back to the kitchen.  A trip that has been
  loaded is the robot's and its own: nothing joins it (the plates are on board) and its stops keep
  their order.
* ``travel(a, b)`` (:class:`Site`): seconds between two places.  The dispatcher node gives planned
  path lengths over the robot's time-optimal speed profile; the tests, straight lines.

The plan
--------
Every robot has a **schedule** (:class:`Schedule`): where it is next free (a place and a time), the
stops left of the trip it is on, and the trips waiting for it at the kitchen.  A pending trip
visits its tables in the order that minimises the weighted sum of its orders' completion times
(every order of ``exact_stops`` stops or fewer, 720 orders for 6; beyond that the cheapest next
stop first).  A new order goes where it adds the least weighted wait to the orders already planned
-- into any robot's pending trip with room, or as a new trip at any place in a robot's queue, so an
urgent order may go before others --, the cost being the change of the weighted sum of waits of all
that robot's orders (:meth:`Planner.insert`).  An order naming a robot goes to that robot only.
This is the insertion heuristic of dial-a-ride planning; Open-RMF's task allocation uses the same
cost (sum of finish times minus earliest starts).

A robot that breaks down, stops reporting or is paused by staff gives back every order it has not
served (:func:`withdraw`: its waiting trips' and the unserved ones of the trip it is on) and is
marked unavailable; those orders are inserted again, onto the robots still in service.

Baselines for the benchmark (:class:`NearestIdle`): one order per trip, first come first served, each
to the robot that is free first (the nearest idle robot when all wait at the kitchen).

:func:`simulate` plays a stream of orders through a policy with the robots driving exactly their
schedules (no ROS, no physics): the figures of a planner alone.
"""
from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass, field

STOPS_CACHE = 10000     # visiting orders remembered by the planner (a few MB at most)


class DispatchError(ValueError):
    """An order or a robot the planner cannot take (the message says why)."""


@dataclass(frozen=True)
class Order:
    """Plates for ``tables`` (names), ordered at ``created`` s; ``priority`` >= 1 weights its wait;
    ``robot``: only this robot may serve it ("" = any)."""

    id: str
    tables: tuple[str, ...]
    created: float
    priority: float = 1.0
    robot: str = ""

    def __post_init__(self) -> None:
        if not self.id:
            raise DispatchError("an order needs an id")
        if not self.tables or any(not t for t in self.tables):
            raise DispatchError(f"order {self.id}: needs at least one table, got {list(self.tables)}")
        if not (math.isfinite(self.priority) and self.priority >= 1.0):
            raise DispatchError(f"order {self.id}: priority must be a number >= 1, got {self.priority}")
        if not math.isfinite(self.created):
            raise DispatchError(f"order {self.id}: created must be a finite time, got {self.created}")


@dataclass(frozen=True)
class Site:
    """The kitchen's name, the seconds ``travel(a, b)`` between places, the metres ``distance(a, b)``
    (for the km driven), and the stop times."""

    kitchen: str
    travel: Callable[[str, str], float]
    distance: Callable[[str, str], float]
    load_s: float = 20.0        # s at the kitchen to load a trip
    serve_s: float = 15.0       # s at each table (plates taken off)


@dataclass
class Trip:
    """Orders loaded together; ``stops``: its tables in visiting order (set by :func:`best_order`)."""

    orders: list[Order] = field(default_factory=list)
    stops: list[str] = field(default_factory=list)

    def tables(self) -> list[str]:
        """Each table of its orders once, in the order first asked for."""
        return list(dict.fromkeys(t for o in self.orders for t in o.tables))


@dataclass
class Schedule:
    """A robot's plan: free at ``place`` at ``free_at`` s after the ``current`` trip (loaded; ``None`` when
    it has none), then the ``pending`` trips, loaded one by one at the kitchen."""

    robot: str
    place: str
    free_at: float
    capacity: int = 3
    current: Trip | None = None
    pending: list[Trip] = field(default_factory=list)
    served: dict[str, float] = field(default_factory=dict)   # order id -> when its last table was served
    metres: float = 0.0                                      # driven so far (simulate)
    available: bool = True      # False: broken down, paused by staff or charging; nothing new is planned for it


def completion_times(site: Site, start: str, t0: float, trip: Trip,
                     stops: Sequence[str]) -> tuple[dict[str, float], float, str]:
    """``trip`` driven from ``start`` at ``t0`` s: to the kitchen, loaded, its ``stops`` in turn, back.
    Returns (order id -> when its last table is served, when back at the kitchen, the kitchen)."""
    t = t0 + site.travel(start, site.kitchen) + site.load_s
    here, at = site.kitchen, {}
    for s in stops:
        t += site.travel(here, s) + site.serve_s
        here = s
        at[s] = t
    done = {o.id: max(at[x] for x in o.tables) for o in trip.orders}
    return done, t + site.travel(here, site.kitchen), site.kitchen


def _weighted_wait(trip: Trip, done: dict[str, float]) -> float:
    return sum(o.priority * (done[o.id] - o.created) for o in trip.orders)


def best_order(site: Site, trip: Trip, exact_stops: int = 6) -> list[str]:
    """The trip's tables in the visiting order that minimises its orders' weighted waits: every order
    for ``exact_stops`` tables or fewer, else the nearest table first, weighed by what it completes
    (greedy).  Where and when the trip starts shifts every completion time alike, so it does not
    matter."""
    tables = trip.tables()
    if len(tables) <= exact_stops:
        return list(min(itertools.permutations(tables), key=lambda p: _weighted_wait(
            trip, completion_times(site, site.kitchen, 0.0, trip, p)[0])))
    order: list[str] = []
    here, left = site.kitchen, set(tables)
    while left:
        def score(s: str, here: str = here) -> float:
            done = set(order) | {s}
            gain = sum(o.priority for o in trip.orders if set(o.tables) <= done)
            return site.travel(here, s) / (1.0 + gain)
        nxt = min(sorted(left), key=score)
        order.append(nxt)
        left.discard(nxt)
        here = nxt
    return order


def _drive(site: Site, sch: Schedule, now: float, trips: list[Trip],
           stops_of: Callable[[Trip], list[str]]) -> tuple[float, list[list[str]], float, str]:
    """``trips`` driven one after the other once ``sch``'s robot is free (from ``now`` at the earliest),
    each along ``stops_of(trip)``: (weighted sum of their orders' waits, each trip's stops, when the
    robot is free after them, where)."""
    cost, stops = 0.0, []
    place, t = sch.place, max(sch.free_at, now)
    for trip in trips:
        s = stops_of(trip)
        done, t, place = completion_times(site, place, t, trip, s)
        cost += _weighted_wait(trip, done)
        stops.append(s)
    return cost, stops, t, place


def schedule_cost(site: Site, sch: Schedule, now: float, pending: list[Trip] | None = None,
                  orders: Callable[[Trip], list[str]] | None = None) -> tuple[float, list[list[str]]]:
    """(weighted sum of the waits of the orders in ``pending`` (default: the schedule's), driven after
    the trip the robot is on, from ``now`` at the earliest; each of those trips' stops).  ``orders``
    gives a trip's stops (default :func:`best_order`)."""
    cost, stops, _, _ = _drive(site, sch, now, sch.pending if pending is None else pending,
                               orders or (lambda tr: best_order(site, tr)))
    return cost, stops


def _nobody(order: Order) -> str:
    return f"order {order.id}: no robot may serve it" + (f" (it asks for {order.robot})" if order.robot else "")


class Planner:
    """Insertion planning over the robots' schedules (module docstring)."""

    name = "insertion"

    def __init__(self, site: Site) -> None:
        self.site = site
        self._stops: dict[tuple, list[str]] = {}    # a trip's orders (tables, priority) -> best stops

    def stops(self, trip: Trip) -> list[str]:
        """:func:`best_order` of ``trip``, remembered by its orders' tables and priorities."""
        key = tuple(sorted((o.tables, o.priority) for o in trip.orders))
        if key not in self._stops:
            if len(self._stops) >= STOPS_CACHE:      # a long-running dispatcher: forget, do not grow
                self._stops.clear()
            self._stops[key] = best_order(self.site, trip)
        return self._stops[key]

    def insert(self, order: Order, schedules: Iterable[Schedule], now: float) -> Schedule:
        """Put ``order`` where it adds the least weighted wait (planning from ``now`` s); returns the
        schedule it went to.  Raises DispatchError when no robot may take it."""
        best: tuple[float, str, Schedule, list[Trip], list[list[str]]] | None = None
        for sch in schedules:
            if not sch.available or (order.robot and order.robot != sch.robot):
                continue
            before, _ = schedule_cost(self.site, sch, now, orders=self.stops)
            for option in self._options(order, sch):
                after, stops = schedule_cost(self.site, sch, now, option, self.stops)
                key = (after - before, sch.robot)
                if best is None or key < (best[0], best[1]):
                    best = (after - before, sch.robot, sch, option, stops)
        if best is None:
            raise DispatchError(_nobody(order))
        _, _, sch, option, stops = best
        for trip, s in zip(option, stops, strict=True):
            trip.stops = s
        sch.pending = option
        return sch

    def _options(self, order: Order, sch: Schedule) -> list[list[Trip]]:
        """Every way to add ``order`` to ``sch``'s pending trips (new lists, the trips copied)."""
        def copy() -> list[Trip]:
            return [Trip(list(t.orders), list(t.stops)) for t in sch.pending]
        out = []
        for i, trip in enumerate(sch.pending):
            if len(trip.orders) < sch.capacity:
                trips = copy()
                trips[i].orders.append(order)
                out.append(trips)
        for i in range(len(sch.pending) + 1):
            trips = copy()
            trips.insert(i, Trip([order]))
            out.append(trips)
        return out


class NearestIdle:
    """The baseline: one order per trip, first come first served, to the robot free first."""

    name = "nearest idle, one order per trip"

    def __init__(self, site: Site) -> None:
        self.site = site

    def insert(self, order: Order, schedules: Iterable[Schedule], now: float) -> Schedule:
        """Append ``order`` as a trip of its own to the robot that is back at the kitchen first."""
        def ready(sch: Schedule) -> float:
            _, _, t, place = _drive(self.site, sch, now, sch.pending, lambda trip: trip.stops)
            return t + self.site.travel(place, self.site.kitchen)
        fit = [s for s in schedules if s.available and (not order.robot or s.robot == order.robot)]
        if not fit:
            raise DispatchError(_nobody(order))
        sch = min(fit, key=lambda s: (ready(s), s.robot))
        trip = Trip([order])
        trip.stops = trip.tables()
        sch.pending.append(trip)
        return sch


def advance(site: Site, sch: Schedule, now: float) -> None:
    """Move ``sch`` on to ``now`` s: a robot free by then has loaded its next pending trip (it loads as
    soon as it is free, so only trips not started by ``now`` may still change); the served times and
    metres of a loaded trip are booked when it is loaded.  An idle robot is free from ``now`` on."""
    while sch.free_at <= now and sch.pending:
        trip = sch.pending.pop(0)
        t0 = max(sch.free_at, max(o.created for o in trip.orders))     # not before its orders were made
        done, back, place = completion_times(site, sch.place, t0, trip, trip.stops)
        route = [sch.place, site.kitchen, *trip.stops, site.kitchen]
        sch.metres += sum(site.distance(a, b) for a, b in itertools.pairwise(route))
        sch.served.update(done)
        sch.current, sch.free_at, sch.place = trip, back, place
    if sch.free_at <= now:
        sch.current = None
        sch.free_at = now


def withdraw(sch: Schedule, now: float) -> list[Order]:
    """Take back every order ``sch``'s robot has not served by ``now`` s -- its waiting trips' and the
    unserved ones of the trip it is on (its plates must be made again) -- oldest first, for planning
    onto the other robots: the robot broke down or stopped reporting, or staff paused it.  It stands
    free from ``now`` (where it is stays its last place; the metres of a cut-short trip count whole)."""
    back = [o for trip in sch.pending for o in trip.orders]
    sch.pending = []
    if sch.current is not None and sch.free_at > now:
        for o in sch.current.orders:
            if sch.served.get(o.id, math.inf) > now:
                back.append(o)
                sch.served.pop(o.id, None)
        sch.current = None
        sch.free_at = now
    return sorted(back, key=lambda o: (o.created, o.id))


@dataclass(frozen=True)
class Outage:
    """A robot out of service from ``start`` until ``end`` s (:func:`simulate`); back at the kitchen."""

    robot: str
    start: float
    end: float


@dataclass(frozen=True)
class Outcome:
    """:func:`simulate`'s figures: every order's wait (s), the last plate's time, metres driven."""

    waits: dict[str, float]
    makespan: float
    metres: float

    def percentile(self, q: float) -> float:
        """The ``q``-th percentile (0..100, nearest rank) of the waits."""
        w = sorted(self.waits.values())
        return w[min(len(w) - 1, max(0, math.ceil(q / 100.0 * len(w)) - 1))]


def simulate(site: Site, policy: Planner | NearestIdle, orders: Sequence[Order], robots: Sequence[str],
             capacity: int = 3, start: str | None = None, outages: Sequence[Outage] = ()) -> Outcome:
    """Play ``orders`` (by creation time) through ``policy`` with ``robots`` waiting at ``start`` (the
    kitchen) at time 0; every robot drives its schedule exactly.  During an ``outage`` a robot's
    unserved orders are planned onto the others at once (:func:`withdraw`); orders no robot may take
    wait until one is back.  DispatchError if an order is lost or served twice."""
    if not robots:
        raise DispatchError("simulate: no robots")
    ids = [o.id for o in orders]
    if len(set(ids)) != len(ids):
        raise DispatchError("simulate: order ids must be unique")
    schedules = {r: Schedule(r, start or site.kitchen, 0.0, capacity) for r in robots}
    for out in outages:
        if out.robot not in schedules or not out.start <= out.end:
            raise DispatchError(f"simulate: bad outage {out} (robots {list(robots)})")
    # events in time order; at equal times robots come back, then break down, then orders arrive
    events = sorted([(o.created, 2, k, o) for k, o in enumerate(orders)]
                    + [(x.start, 1, k, x) for k, x in enumerate(outages)]
                    + [(x.end, 0, k, x) for k, x in enumerate(outages)], key=lambda e: e[:3])
    waiting: list[Order] = []            # orders no robot could take (all out of service)

    def plan(order: Order, t: float) -> None:
        try:
            policy.insert(order, schedules.values(), t)
        except DispatchError:
            waiting.append(order)

    for t, kind, _, what in events:
        for sch in schedules.values():
            advance(site, sch, t)
        if kind == 2:
            plan(what, t)
        elif kind == 1:
            sch = schedules[what.robot]
            sch.available = False
            for order in withdraw(sch, t):
                plan(order, t)
        else:
            sch = schedules[what.robot]
            if not sch.available and not any(x.robot == what.robot and x.start <= t < x.end for x in outages):
                sch.available, sch.place, sch.free_at = True, site.kitchen, max(sch.free_at, t)
                again, waiting[:] = list(waiting), []
                for order in again:
                    plan(order, t)
        for sch in schedules.values():
            advance(site, sch, t)
    for sch in schedules.values():
        advance(site, sch, math.inf)
    served: dict[str, float] = {}
    for sch in schedules.values():
        for k, v in sch.served.items():
            if k in served:
                raise DispatchError(f"simulate: order {k} served twice")
            served[k] = v
    missing = set(ids) - set(served)
    if missing:
        raise DispatchError(f"simulate: orders never served: {sorted(missing)}")
    by_id = {o.id: o for o in orders}
    return Outcome({k: served[k] - by_id[k].created for k in ids}, max(served.values(), default=0.0),
                   sum(s.metres for s in schedules.values()))
