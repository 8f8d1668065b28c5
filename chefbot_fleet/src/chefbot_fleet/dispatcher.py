"""The fleet dispatcher's logic (pure; no rospy): orders in, robots sent, faults handled, nothing lost.

:class:`Dispatcher` keeps the queue in an :class:`~chefbot_fleet.order_store.OrderStore` and plans
it with :mod:`chefbot_fleet.dispatch` (insertion planning, or the nearest-idle baseline).  The
``dispatcher`` node feeds it what happens -- orders, cancellations, staff commands, each robot's
reports on ``/fleet/robots``, the results of the move_base goals it sent -- and carries out its
:class:`Goto` and :class:`Stop` commands.  Times are float seconds of one clock (the node's ROS time).

A robot's trip, leg by leg::

    to_kitchen --arrived--> loading (load_s) --> delivering --arrived--> serving (serve_s) --> ... --+
        ^                                                                                          |
        +--- its next trip, when the kitchen is free <--- the trip's last table ---> parking --> idle

* **The kitchen is one robot's at a time**: a robot is sent there only when no other robot is on its
  way there or loading; meanwhile it waits at its parking pose.
* An order is ``assigned`` while its trip waits, ``loading`` at the kitchen, ``on_the_way`` once its
  plates are on board, and ``served`` when the robot stands at its last table.
* **A leg that fails** (move_base aborts it, or the robot has not moved ``stall_s`` while driving) is
  sent again after ``retry_wait_s``, ``retries`` times; then the robot is in ``fault``.  A robot in
  fault, paused by staff, or not heard from for ``stale_s`` (``offline``) gives back every order it
  has not served (:func:`~chefbot_fleet.dispatch.withdraw`): they become ``queued`` again, with the
  reason, and are planned onto the robots still in service at once; plates already on board must be
  made again.  A paused robot takes orders again after ``resume``; an offline one as soon as it
  reports again; one in fault after ``resume``, or by itself ``recover_s`` later when it reaches its
  parking pose (a passing cause: another robot in the way, a localization upset).
* **Lost** (:meth:`Dispatcher.localization`, when the robot's localization reports its health): a
  robot whose localization has said it is not sure where the robot is (not localized, a poor fit,
  no scans) for ``lost_s`` is ``lost``: stopped, its unserved orders planned onto the others as for
  a fault.  It is not sent anywhere while lost (and a robot in fault is not sent to its parking pose
  while its localization is in doubt); once its localization is sure again (amcl recovered by
  itself, or staff gave it its pose) it drives to its parking pose and is back in service.
* **charge**: the robot finishes the trip it is on, gives back its waiting trips, drives to its
  charger and stays there (``charging``) until ``resume``.
* **Batteries** (:meth:`Dispatcher.battery`, when the robot reports one): below ``low_battery`` a robot
  is sent to charge as above; charging, it is back in service by itself once it reaches
  ``charged_battery``.  A robot without a charger pose is only warned about (its reason).
* **Cancelling** an order takes it out of its trip; a robot carrying its plates skips its tables
  unless another order of the trip needs them.
* **Restart**: a new Dispatcher on the same store resumes the queue.  Orders that were loading or on
  the way stay with their robot (its current trip, from wherever it reports); assigned ones go back
  into their robot's waiting trips; queued ones are planned.  A robot that does not report within
  ``stale_s`` gives them back as above.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

from chefbot_common.geometry import Pose2D
from chefbot_fleet.dispatch import (
    DispatchError,
    NearestIdle,
    Order,
    Planner,
    Schedule,
    Site,
    Trip,
    best_order,
    completion_times,
)
from chefbot_fleet.order_store import FINAL, OrderStore, StoredOrder
from chefbot_fleet.travel import Places

POLICIES = {"insertion": Planner, "nearest_idle": NearestIdle}
OUT_OF_SERVICE = ("paused", "fault", "offline", "lost", "to_charger", "charging")
MOVED_M = 0.10          # m: a driving robot that moved less than this in stall_s is stalled
PARKED_M = 0.25         # m: a robot this close to its parking pose is parked


@dataclass(frozen=True)
class Goto:
    """Send ``robot`` to the place ``place`` (a name of :class:`~chefbot_fleet.travel.Places`); the
    result comes back through :meth:`Dispatcher.leg_done` with ``leg``."""

    robot: str
    place: str
    leg: int


@dataclass(frozen=True)
class Stop:
    """Cancel ``robot``'s goal: it stands still."""

    robot: str


@dataclass(frozen=True)
class Config:
    """The dispatcher's settings (the node's parameters of the same names)."""

    capacity: int = 3
    policy: str = "insertion"
    retries: int = 2
    retry_wait_s: float = 5.0
    stale_s: float = 10.0
    stall_s: float = 90.0
    recover_s: float = 60.0     # a robot in fault is sent to its parking pose after this long (0: only staff resume it)
    low_battery: float = 0.25   # state of charge (0..1) below which a robot goes to charge after its trip
    charged_battery: float = 0.9   # ... and at which it is back in service
    lost_s: float = 15.0        # a robot whose localization is in doubt this long is lost (0: never)
    keep_final: int = 50        # final orders kept in the published queue

    def __post_init__(self) -> None:
        if self.capacity < 1:
            raise ValueError(f"capacity must be >= 1, got {self.capacity}")
        if self.policy not in POLICIES:
            raise ValueError(f"policy must be one of {', '.join(POLICIES)}, got {self.policy!r}")
        if self.retries < 0:
            raise ValueError(f"retries must be >= 0, got {self.retries}")
        if not 0.0 <= self.low_battery < self.charged_battery <= 1.0:
            raise ValueError(f"need 0 <= low_battery < charged_battery <= 1, got {self.low_battery}, "
                             f"{self.charged_battery}")
        for name in ("recover_s", "lost_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"{name} must be a number >= 0, got {v}")
        for name in ("retry_wait_s", "stale_s", "stall_s"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a number > 0, got {v}")


@dataclass
class Robot:
    """One robot as the dispatcher drives it."""

    name: str
    parking: str                 # place names
    charger: str | None
    schedule: Schedule
    state: str = "offline"       # see FleetRobot.msg
    place: str = ""              # where it is driving or standing
    stops: list[str] = field(default_factory=list)     # its trip's tables not yet reached
    leg: int = 0                 # the id of the Goto it is carrying out (0: none)
    leg_started: float = 0.0
    leg_expect_s: float = 0.0
    wait_until: float = 0.0      # end of loading / serving / a retry's wait
    tries: int = 0
    reason: str = ""
    last_seen: float = -math.inf
    pose: Pose2D | None = None
    moved_at: float = 0.0        # when it last moved MOVED_M from moved_from
    moved_from: Pose2D | None = None
    retry_place: str = ""        # the leg to send again when wait_until passes (state 'retrying')
    charge_after: bool = False   # staff asked it to charge after its trip
    fault_since: float = 0.0     # when it went into fault
    battery: float = -1.0        # state of charge 0..1 (-1: not reported)
    for_battery: bool = False    # it went to charge because its battery was low (back by itself when charged)
    doubt_since: float | None = None   # since when its localization has been in doubt (None: sure, or not reported)
    doubt: str = ""              # what its localization says then

    @property
    def here(self) -> str:
        """The place name of its last reported pose."""
        return f"@{self.name}"


LOCALIZATION_STATUS = ": localization"   # a localizer's diagnostics status name ends so ("/NAME/amcl: localization")


def localization_report(statuses: list[tuple[str, int, str]]) -> tuple[bool, str] | None:
    """A robot's localization health from its ``diagnostics`` statuses, as (name, level, message)
    (``diagnostic_msgs/DiagnosticStatus`` levels: 0 OK, 1 WARN, 2 ERROR, 3 STALE): (sure, message) of
    the first status named ``...: localization``, sure only when it is OK; None when there is none
    (another node's diagnostics)."""
    for name, level, message in statuses:
        if name.endswith(LOCALIZATION_STATUS):
            return level == 0, message
    return None


def parking_place(robot: str) -> str:
    """The place name of ``robot``'s parking pose."""
    return f"parking:{robot}"


def charger_place(robot: str) -> str:
    """The place name of ``robot``'s charger pose."""
    return f"charger:{robot}"


class Dispatcher:
    """The queue, the plan and every robot's trip (module docstring).  ``places`` holds the tables,
    ``kitchen`` and :func:`parking_place` / :func:`charger_place` of every robot; ``robots``: their
    names, in fleet order; ``tables``: the names orders may ask for."""

    def __init__(self, store: OrderStore, places: Places, kitchen: str, tables: list[str], robots: list[str],
                 now: float, config: Config | None = None, load_s: float = 20.0, serve_s: float = 15.0) -> None:
        self.cfg = config or Config()
        self.store = store
        self.places = places
        self.tables = set(tables)
        if not robots:
            raise ValueError("the dispatcher needs at least one robot")
        for name in [kitchen, *tables, *(parking_place(r) for r in robots)]:
            places.pose(name)           # KeyError names a missing place
        self.site = Site(kitchen, places.travel, places.distance, load_s=load_s, serve_s=serve_s)
        self.policy = POLICIES[self.cfg.policy](self.site)
        self.robots: dict[str, Robot] = {}
        for r in robots:
            charger = charger_place(r) if charger_place(r) in places else None
            sch = Schedule(r, parking_place(r), now, self.cfg.capacity, available=False)
            self.robots[r] = Robot(r, parking_place(r), charger, sch, place=parking_place(r), last_seen=now,
                                   moved_at=now)
        self._legs = 0
        self._commands: list[Goto | Stop] = []
        self.waiting: list[str] = []        # order ids no robot could take yet
        self.changed = True                 # something to publish
        self._resume(now)

    # ------------------------------------------------------------------ inputs
    def deliver(self, tables: list[str], priority: float, robot: str, now: float) -> StoredOrder:
        """A new order (ValueError names what is wrong with it); planned at once."""
        tables = [str(t) for t in tables]
        unknown = [t for t in tables if t not in self.tables]
        if unknown:
            raise ValueError(f"unknown table(s) {unknown}; tables: {', '.join(sorted(self.tables))}")
        if len(set(tables)) != len(tables):
            raise ValueError(f"a table is listed twice: {tables}")
        if robot and robot not in self.robots:
            raise ValueError(f"unknown robot {robot!r}; robots: {', '.join(self.robots)}")
        priority = 1.0 if priority == 0 else float(priority)
        stored = self.store.add(tables, now, priority, robot)
        self._plan(stored.id, now)
        return self.store.get(stored.id)

    def cancel(self, order_id: str, now: float) -> str:
        """Cancel an order; returns what happened (KeyError: no such order; ValueError: it is final)."""
        o = self.store.get(order_id)
        if o.state in FINAL:
            raise ValueError(f"order {order_id} is already {o.state}")
        if order_id in self.waiting:
            self.waiting.remove(order_id)
        for r in self.robots.values():
            self._drop(r, order_id, now)
        self.store.move(order_id, "cancelled", now, reason="cancelled by staff")
        self.changed = True
        return f"order {order_id} cancelled"

    def set_robot(self, name: str, command: str, now: float) -> str:
        """Staff's ``pause``, ``resume`` or ``charge`` of robot ``name`` (ValueError says why not)."""
        r = self.robots.get(name)
        if r is None:
            raise ValueError(f"unknown robot {name!r}; robots: {', '.join(self.robots)}")
        if command == "pause":
            self._out_of_service(r, "paused", "paused by staff", now)
            return f"{name} paused; its orders go to the other robots"
        if command == "resume":
            if r.state == "offline":
                raise ValueError(f"{name} is offline (not heard from for {self.cfg.stale_s:g} s): it resumes "
                                 "by itself when it reports again")
            if r.state not in OUT_OF_SERVICE:     # offline: above
                return f"{name} is {r.state}: nothing to resume"
            if r.state == "lost":        # staff vouch for its pose (e.g. gave it with RViz's 2D Pose Estimate)
                r.doubt_since, r.doubt = None, ""
            self._home(r, now)        # from wherever it stopped (a new trip may come first)
            self._replan_waiting(now)
            return f"{name} takes orders again"
        if command == "charge":
            if r.charger is None:
                raise ValueError(f"{name} has no charger pose in the fleet file")
            r.charge_after, r.for_battery = True, False
            for order in self._withdraw_pending(r, now, f"{name} goes to its charger"):
                self._plan(order, now)
            if r.schedule.current is None:
                self._send(r, "to_charger", r.charger, now)
            self.changed = True
            return f"{name} goes to its charger" + (" after its trip" if r.schedule.current else "")
        raise ValueError(f"unknown command {command!r}: pause, resume or charge")

    def battery(self, name: str, fraction: float, now: float) -> None:
        """Robot ``name``'s battery state of charge (0..1; NaN or out of range: ignored)."""
        r = self.robots.get(name)
        if r is None or not (math.isfinite(fraction) and 0.0 <= fraction <= 1.0):
            return
        r.battery = fraction
        low = fraction < self.cfg.low_battery
        if r.state == "charging" and r.for_battery and fraction >= self.cfg.charged_battery:
            self._home(r, now)
            self._replan_waiting(now)
        elif low and not r.charge_after and r.state not in OUT_OF_SERVICE:      # not a paused robot
            why = f"battery {100 * fraction:.0f} %"
            if r.charger is None:
                if r.reason != f"{why}, no charger pose":
                    r.reason, self.changed = f"{why}, no charger pose", True
                return
            self.set_robot(name, "charge", now)
            r.for_battery, r.reason = True, f"{why}: charging after its trip"

    def localization(self, name: str, sure: bool, message: str, now: float) -> None:
        """Robot ``name``'s localization reported its health: ``sure`` of the pose, or not (``message``
        says why: not localized, the scan does not fit the map, no scans)."""
        r = self.robots.get(name)
        if r is None:
            return
        if not sure:
            if r.doubt_since is None:
                r.doubt_since = now
            r.doubt = message
            return
        r.doubt_since, r.doubt = None, ""
        if r.state == "lost":
            self._home(r, now)           # localized again: to its parking pose, and in service
            self._replan_waiting(now)

    def heard(self, name: str, pose: Pose2D, now: float, waiting: bool = False) -> None:
        """Robot ``name`` reported its pose (``waiting``: its navigation says it waits on purpose, e.g.
        outside a single-lane zone, so it is not stalled)."""
        r = self.robots.get(name)
        if r is None:
            return
        r.last_seen, r.pose = now, pose
        self.places.set(r.here, pose)
        if r.moved_from is None or r.moved_from.distance(pose) > MOVED_M or waiting:
            r.moved_from, r.moved_at = pose, now
        if r.state == "offline":
            r.reason = ""
            if r.schedule.current is not None:      # restarted dispatcher: the plates on board go on
                self._next_stop(r, now)
            elif r.schedule.pending:                 # restarted dispatcher: its waiting trips go on
                self._idle(r, now, "")
            else:                                    # back from silence, or a new dispatcher: to its parking pose
                self._home(r, now)
            self._replan_waiting(now)

    def leg_done(self, name: str, leg: int, ok: bool, reason: str, now: float) -> None:
        """The result of :class:`Goto` ``leg`` of robot ``name`` (ignored when the robot has moved on)."""
        r = self.robots.get(name)
        if r is None or leg != r.leg or r.leg == 0:
            return
        r.leg = 0
        if not ok:
            self._leg_failed(r, reason, now)
            return
        r.tries = 0
        if r.state == "to_kitchen":
            if not r.schedule.pending:          # its orders were cancelled or planned elsewhere meanwhile
                self._next_stop(r, now)
                return
            trip = r.schedule.pending.pop(0)
            r.schedule.current, r.stops = trip, list(trip.stops)
            r.state, r.wait_until = "loading", now + self.site.load_s
            for o in self._trip_ids(r):
                self._move(o, "loading", now, r.name)
        elif r.state == "delivering":
            table = r.stops.pop(0)
            r.state, r.wait_until = "serving", now + self.site.serve_s
            self._served_at(r, table, now)
        elif r.state == "parking":
            self._idle(r, now, "")
        elif r.state == "to_charger":
            r.state, r.charge_after = "charging", False
        self.changed = True

    def tick(self, now: float) -> None:
        """Time passes: loading and serving end, retries are sent, silent and stalled robots are caught,
        robots start their next trips."""
        for r in self.robots.values():
            holds = r.schedule.current is not None or bool(r.schedule.pending)
            if (r.state != "offline" or holds) and now - r.last_seen > self.cfg.stale_s:
                self._out_of_service(r, "offline", f"{r.name} has not reported for {now - r.last_seen:.0f} s", now)
                continue
            if self.cfg.lost_s > 0 and r.doubt_since is not None and now - r.doubt_since >= self.cfg.lost_s \
                    and r.state not in ("lost", "offline", "paused", "charging"):
                self._out_of_service(r, "lost", f"{r.name} is lost for {now - r.doubt_since:.0f} s: {r.doubt}", now)
                continue
            if r.leg and r.state in ("to_kitchen", "delivering", "parking", "to_charger") \
                    and now - r.moved_at > self.cfg.stall_s:
                self._commands.append(Stop(r.name))
                r.leg = 0
                self._leg_failed(r, f"has not moved for {now - r.moved_at:.0f} s", now)
                continue
            if r.state == "fault" and self.cfg.recover_s > 0 and now - r.fault_since >= self.cfg.recover_s \
                    and r.doubt_since is None:
                # a leg that failed for a passing reason (another robot in the way, a localization upset)
                # should not keep the robot out for good: if it reaches its parking pose it is back in service
                self._send(r, "parking", r.parking, now)
                continue
            if r.wait_until > now:
                continue
            if r.state == "loading":
                for o in self._trip_ids(r):
                    self._move(o, "on_the_way", now, r.name)
                self._next_stop(r, now)
            elif r.state == "serving":
                self._next_stop(r, now)
            elif r.state == "retrying":
                r.state = r.retry_place
                self._goto(r, r.place, now)
        if self.waiting:
            self._replan_waiting(now)
        for r in self.robots.values():
            if r.state in ("idle", "parking") and r.schedule.pending and self._kitchen_free():
                self._start_trip(r, now)

    def commands(self) -> list[Goto | Stop]:
        """The commands since the last call, in order."""
        out, self._commands = self._commands, []
        return out

    # ------------------------------------------------------------------ what the node publishes
    def etas(self, now: float) -> dict[str, float]:
        """Order id -> planned seconds from ``now`` until its last table is served."""
        out: dict[str, float] = {}
        for r in self.robots.values():
            sch = self._refresh(r, now, out)
            place, t = sch.place, sch.free_at
            for trip in sch.pending:
                done, t, place = completion_times(self.site, place, t, trip, trip.stops)
                out.update({k: v - self.site.serve_s - now for k, v in done.items()})   # served on arrival
        return out

    def robot_orders(self, name: str) -> list[str]:
        """The ids of the orders robot ``name`` carries or will carry, its current trip's first."""
        sch = self.robots[name].schedule
        trips = ([sch.current] if sch.current else []) + sch.pending
        return [o.id for trip in trips for o in trip.orders]

    # ------------------------------------------------------------------ internals
    def _resume(self, now: float) -> None:
        """Rebuild the plan from the store (a restarted dispatcher)."""
        carried: dict[str, list[StoredOrder]] = {}
        assigned: dict[str, list[StoredOrder]] = {}
        for o in self.store.orders(open_only=True):
            if o.state in ("loading", "on_the_way") and o.assigned in self.robots:
                carried.setdefault(o.assigned, []).append(o)
            elif o.state == "assigned" and o.assigned in self.robots:
                assigned.setdefault(o.assigned, []).append(o)
            else:
                if o.state != "queued":
                    self._move(o.id, "queued", now, reason=f"its robot {o.assigned!r} is not in the fleet")
                self.waiting.append(o.id)
        for name, orders in carried.items():
            r = self.robots[name]
            trip = Trip([self._order(o) for o in orders])
            trip.stops = best_order(self.site, trip)
            r.schedule.current, r.stops = trip, list(trip.stops)
            for o in orders:
                if o.state == "loading":
                    self._move(o.id, "on_the_way", now, name)
        for name, orders in assigned.items():
            sch = self.robots[name].schedule
            for k in range(0, len(orders), self.cfg.capacity):
                trip = Trip([self._order(o) for o in orders[k:k + self.cfg.capacity]])
                trip.stops = best_order(self.site, trip)
                sch.pending.append(trip)

    def _order(self, o: StoredOrder) -> Order:
        return Order(o.id, tuple(o.tables), o.created, o.priority, o.robot)

    def _move(self, order_id: str, state: str, now: float, robot: str = "", reason: str = "") -> None:
        if self.store.get(order_id).state != state:
            self.store.move(order_id, state, now, robot, reason)
            self.changed = True

    def _refresh(self, r: Robot, now: float, etas: dict[str, float] | None = None) -> Schedule:
        """The robot's Schedule as the planner needs it now: available or not, where and when it is free
        (its current trip's orders' ETAs into ``etas``)."""
        sch = r.schedule
        sch.available = r.state not in OUT_OF_SERVICE and not r.charge_after
        if sch.current is not None:
            back = self._current_eta(r, now, {} if etas is None else etas)
            sch.place, sch.free_at = self.site.kitchen, back
        elif r.state == "to_kitchen" or (r.state == "retrying" and r.retry_place == "to_kitchen"):
            sch.place, sch.free_at = self.site.kitchen, self._leg_end(r, now)
        else:
            sch.place = r.here if r.pose is not None else r.place
            sch.free_at = now
        return sch

    def _current_eta(self, r: Robot, now: float, out: dict[str, float]) -> float:
        """When the robot is back at the kitchen after its current trip (and its orders' ETAs into ``out``)."""
        trip = r.schedule.current
        assert trip is not None
        t = max(now, r.wait_until) if r.state in ("loading", "serving") else self._leg_end(r, now)
        here = r.place or self.site.kitchen
        stops = list(r.stops)
        if r.state in ("delivering", "retrying") and stops and here == stops[0]:
            t += self.site.serve_s
            out.update({o.id: t - self.site.serve_s - now for o in trip.orders
                        if set(o.tables) & set(stops) == {stops[0]}})
            stops = stops[1:]
        at: dict[str, float] = {}
        for s in stops:
            t += self.site.travel(here, s) + self.site.serve_s
            at[s], here = t - self.site.serve_s, s
        for o in trip.orders:
            times = [at[x] for x in o.tables if x in at]
            if times and o.id not in out:
                out[o.id] = max(times) - now
        return t + self.site.travel(here, self.site.kitchen)

    def _leg_end(self, r: Robot, now: float) -> float:
        """When the robot should reach the place its leg (or the leg it will send again) goes to."""
        if r.state == "retrying":
            return max(now, r.wait_until) + (self.site.travel(r.here, r.place) if r.pose is not None else 0.0)
        return now + max(0.0, r.leg_expect_s - (now - r.leg_started)) if r.leg else now

    def _plan(self, order_id: str, now: float, why: str = "") -> None:
        """Plan one stored order onto a robot in service (``why``: the reason it is planned again, kept with
        its new assignment); keep it waiting when none may take it."""
        o = self.store.get(order_id)
        for r in self.robots.values():
            self._refresh(r, now)
        try:
            sch = self.policy.insert(self._order(o), [r.schedule for r in self.robots.values()], now)
        except DispatchError as exc:
            if order_id not in self.waiting:
                self.waiting.append(order_id)
            if o.state != "queued":
                self._move(order_id, "queued", now, reason=str(exc))
            return
        if order_id in self.waiting:
            self.waiting.remove(order_id)
        self._move(order_id, "assigned", now, sch.robot, f"planned again: {why}" if why else "")
        self.changed = True

    def _replan_waiting(self, now: float) -> None:
        for oid in list(self.waiting):
            self._plan(oid, now)

    def _trip_ids(self, r: Robot) -> list[str]:
        trip = r.schedule.current
        return [o.id for o in trip.orders] if trip else []

    def _kitchen_free(self) -> bool:
        return not any(r.state in ("to_kitchen", "loading") or (r.state == "retrying" and r.retry_place == "to_kitchen")
                       for r in self.robots.values())

    def _start_trip(self, r: Robot, now: float) -> None:
        """To the kitchen for its first waiting trip (which new orders may still join until it is loaded)."""
        self._send(r, "to_kitchen", self.site.kitchen, now)

    def _next_stop(self, r: Robot, now: float) -> None:
        """After loading or serving: on to the next table, else the trip is over."""
        if r.stops:
            self._send(r, "delivering", r.stops[0], now)
            return
        r.schedule.current = None
        if r.charge_after and r.charger:
            self._send(r, "to_charger", r.charger, now)
        elif r.schedule.pending and self._kitchen_free():
            self._start_trip(r, now)
        else:
            self._send(r, "parking", r.parking, now)

    def _served_at(self, r: Robot, table: str, now: float) -> None:
        trip = r.schedule.current
        if trip is None:
            return
        for o in trip.orders:
            if table in o.tables and not (set(o.tables) & set(r.stops)):
                self._move(o.id, "served", now, r.name)

    def _send(self, r: Robot, state: str, place: str, now: float) -> None:
        r.state, r.place, r.tries, r.reason = state, place, 0, ""
        self._goto(r, place, now)
        self.changed = True

    def _goto(self, r: Robot, place: str, now: float) -> None:
        self._legs += 1
        r.leg, r.leg_started = self._legs, now
        r.moved_at, r.moved_from = now, r.pose
        r.leg_expect_s = self.site.travel(r.here, place) if r.pose is not None else 0.0
        self._commands.append(Goto(r.name, place, r.leg))

    def _home(self, r: Robot, now: float) -> None:
        """In service again: idle where it stands when that is its parking pose, else driving there."""
        self._idle(r, now, "")
        park = self.places.pose(r.parking)
        if r.pose is None or r.pose.distance(park) > PARKED_M:
            self._send(r, "parking", r.parking, now)

    def _idle(self, r: Robot, now: float, reason: str) -> None:
        r.state, r.reason, r.leg, r.tries, r.charge_after = "idle", reason, 0, 0, False
        self.changed = True

    def _leg_failed(self, r: Robot, reason: str, now: float) -> None:
        if r.tries < self.cfg.retries:
            r.tries += 1
            r.retry_place, r.state = r.state, "retrying"
            r.wait_until = now + self.cfg.retry_wait_s
            r.reason = f"{reason}; again in {self.cfg.retry_wait_s:g} s ({r.tries}/{self.cfg.retries})"
            self.changed = True
            return
        self._out_of_service(r, "fault", f"{r.name} failed to reach {r.place}: {reason}", now)

    def _withdraw_pending(self, r: Robot, now: float, why: str) -> list[str]:
        """Take back the orders of the robot's waiting trips (queued again with ``why``)."""
        ids = [o.id for trip in r.schedule.pending for o in trip.orders]
        r.schedule.pending = []
        for oid in ids:
            self._move(oid, "queued", now, reason=why)
        return ids

    def _out_of_service(self, r: Robot, state: str, why: str, now: float) -> None:
        """The robot stops taking orders; every order it has not served is planned onto the others."""
        back = self._withdraw_pending(r, now, why)
        if r.schedule.current is not None:
            for o in r.schedule.current.orders:
                if self.store.get(o.id).state not in FINAL:
                    self._move(o.id, "queued", now, reason=why)
                    back.append(o.id)
            r.schedule.current = None
        r.stops = []
        if r.leg or r.state in ("to_kitchen", "delivering", "parking", "to_charger", "retrying"):
            self._commands.append(Stop(r.name))
        r.state, r.reason, r.leg, r.charge_after = state, why, 0, False
        r.place, r.fault_since = "", now
        self.changed = True
        for oid in back:
            self._plan(oid, now, why)

    def _drop(self, r: Robot, order_id: str, now: float) -> None:
        """Take a cancelled order out of the robot's trips; re-route it when its next table is no longer needed."""
        sch = r.schedule
        for trip in list(sch.pending):
            if any(o.id == order_id for o in trip.orders):
                trip.orders = [o for o in trip.orders if o.id != order_id]
                if trip.orders:
                    trip.stops = best_order(self.site, trip)
                else:
                    sch.pending.remove(trip)
        if not sch.pending and sch.current is None and r.state == "to_kitchen":
            self._commands.append(Stop(r.name))        # nothing left to load: it parks
            r.leg = 0
            self._next_stop(r, now)
            return
        trip = sch.current
        if trip is None or not any(o.id == order_id for o in trip.orders):
            return
        trip.orders = [o for o in trip.orders if o.id != order_id]
        needed = {t for o in trip.orders for t in o.tables}
        first = r.stops[0] if r.stops else None
        r.stops = [s for s in r.stops if s in needed]
        if not trip.orders and r.state == "loading":
            r.stops = []
            self._commands.append(Stop(r.name))
            r.leg = 0
            self._next_stop(r, now)
        elif r.state == "delivering" and first is not None and first not in needed:
            self._commands.append(Stop(r.name))
            r.leg = 0
            self._next_stop(r, now)
