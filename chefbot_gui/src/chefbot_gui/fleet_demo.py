"""A stand-in fleet for the fleet window's demo, screenshot and rostest (``nodes/fleet_demo_world``).

Pure Python (no ROS, no Qt), deterministic: a scripted hotel scene — three robots, one
delivering, one on its way to the kitchen, one charging, and a queue of orders in every state —
that then plays on: robots glide along drawn aisle routes (:func:`chefbot_gui.demo_world.aisle_route`)
at a fixed speed, serve their tables, park.  Staff commands behave like the dispatcher's in
outline (an order goes to the robot with the fewest orders; pause gives a robot's orders back;
charge sends it to its charger) so the window can be tried.  Not the dispatcher: no kitchen
loading, no planning, no traffic.  Times in s, distances in m, map frame.
"""
from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from chefbot_gui.demo_world import aisle_route, point_along
from chefbot_gui.geometry import Point, distance, path_length

SERVE_S = 4.0          # at each table
ARRIVED_M = 0.02


@dataclass
class DemoOrder:
    """One order as the stand-in keeps it (states as chefbot_fleet/Order)."""

    id: str
    tables: list[str]
    state: str = "queued"
    assigned: str = ""
    reason: str = ""
    priority: float = 1.0
    robot: str = ""
    eta: float = -1.0


@dataclass
class DemoRobot:
    """One stand-in robot: pose (m, rad), its route ahead, what it is doing (chefbot_fleet/FleetRobot words)."""

    name: str
    x: float
    y: float
    yaw: float
    parking: Point
    charger: Point | None
    state: str = "idle"
    place: str = ""
    stops: list[str] = field(default_factory=list)
    orders: list[str] = field(default_factory=list)
    reason: str = ""
    battery: float = 0.8
    route: list[Point] = field(default_factory=list)
    travelled: float = 0.0        # m along route
    wait_s: float = 0.0           # left at a table


class DemoFleet:
    """The scripted scene and its play; ``speed`` m/s (0: the scene stands still, for screenshots).

    ``places``: map-frame points by name (tables, ``kitchen``); ``robots``: name -> (parking,
    charger or None), in fleet file order (the first three get the scripted roles).
    """

    def __init__(self, places: Mapping[str, Point], robots: Mapping[str, tuple[Point, Point | None]],
                 speed: float = 0.3) -> None:
        if speed < 0 or not math.isfinite(speed):
            raise ValueError(f"speed must be >= 0 m/s, got {speed}")
        self.places = dict(places)
        self.speed = speed
        self.robots = {n: DemoRobot(n, p[0], p[1], 0.0, p, c) for n, (p, c) in robots.items()}
        self.orders: list[DemoOrder] = []
        self._next_id = 1
        self._script()

    # ------------------------------------------------------------------ the scene
    def _new_id(self) -> str:
        oid = f"o{self._next_id}"
        self._next_id += 1
        return oid

    def _script(self) -> None:
        names = list(self.robots)
        tables = [k for k in self.places if k != "kitchen"]
        have = set(tables)
        if len(names) < 3 or not {"table_1", "table_2", "table_3", "table_4", "table_5", "table_7",
                                   "table_9"} <= have or "kitchen" not in self.places:
            return   # another site: robots parked, an empty queue
        a, b, c = (self.robots[n] for n in names[:3])

        def order(tables: list[str], state: str, robot: DemoRobot | None = None, reason: str = "",
                  priority: float = 1.0) -> DemoOrder:
            o = DemoOrder(self._new_id(), tables, state, robot.name if robot else "", reason, priority)
            self.orders.append(o)
            return o

        order(["table_4"], "served")
        o2 = order(["table_2", "table_5"], "on_the_way", a)
        order(["table_1"], "cancelled", reason="cancelled by staff")
        o4 = order(["table_7"], "assigned", b)
        o5 = order(["table_9"], "assigned", b, priority=2.0)
        order(["table_3"], "queued", reason=f"{c.name}: battery 18 %, charging")
        # a: between table 1 and table 2 in the south aisle, delivering
        t1, t2 = self.places["table_1"], self.places["table_2"]
        a.x, a.y = (t1[0] + t2[0]) / 2, t1[1] - 1.5
        a.state, a.place, a.stops, a.orders, a.battery = "delivering", "table_2", ["table_2", "table_5"], [o2.id], 0.74
        self._route(a, [self.places[s] for s in a.stops])
        # b: leaving its parking pose for the kitchen
        b.x, b.y = b.parking[0] + 0.4, b.parking[1] - 0.8
        b.state, b.place, b.stops, b.orders, b.battery = "to_kitchen", "kitchen", ["table_7", "table_9"], \
            [o4.id, o5.id], 0.55
        self._route(b, [self.places["kitchen"]])
        # c: on its charger
        if c.charger is not None:
            c.x, c.y, c.yaw = c.charger[0], c.charger[1], math.pi
        c.state, c.place, c.reason, c.battery = "charging", f"charger:{c.name}", "battery 18 %", 0.18

    def _route(self, r: DemoRobot, targets: Sequence[Point]) -> None:
        pts: list[Point] = [(r.x, r.y)]
        for t in targets:
            for p in aisle_route(pts[-1], t)[1:]:
                pts.append(p)
        r.route, r.travelled = pts, 0.0

    # ------------------------------------------------------------------ staff commands
    def add_order(self, tables: Sequence[str], priority: float = 1.0, robot: str = "") -> DemoOrder:
        """A new order, assigned to ``robot`` or the robot in service with the fewest orders.
        Raises ``ValueError`` (the reason) for an unknown or repeated table or robot."""
        if not tables:
            raise ValueError("an order needs at least one table")
        unknown = [t for t in tables if t not in self.places or t == "kitchen"]
        if unknown:
            raise ValueError(f"unknown table {unknown[0]!r}")
        if len(set(tables)) != len(tables):
            raise ValueError("a table is named twice")
        if robot and robot not in self.robots:
            raise ValueError(f"unknown robot {robot!r}")
        o = DemoOrder(self._new_id(), list(tables), priority=max(1.0, priority), robot=robot)
        self.orders.append(o)
        self._assign(o)
        return o

    def _in_service(self, r: DemoRobot) -> bool:
        return r.state not in ("paused", "fault", "offline", "to_charger", "charging")

    def _assign(self, o: DemoOrder) -> None:
        candidates = [r for r in self.robots.values() if self._in_service(r) and (not o.robot or r.name == o.robot)]
        if not candidates:
            o.state, o.assigned = "queued", ""
            o.reason = o.reason or "no robot in service"
            return
        r = min(candidates, key=lambda r: len(r.orders))
        o.state, o.assigned, o.reason = "assigned", r.name, ""
        r.orders.append(o.id)
        r.stops += [t for t in o.tables if t not in r.stops]
        if r.state in ("idle", "parking"):
            r.state, r.place = "to_kitchen", "kitchen"
            self._route(r, [self.places["kitchen"]])

    def cancel(self, order_id: str) -> str:
        """Cancel an order; returns the message; ``ValueError`` for an unknown or final order."""
        o = self.order(order_id)
        if o.state in ("served", "cancelled", "failed"):
            raise ValueError(f"order {order_id} is already {o.state}")
        o.state, o.reason = "cancelled", "cancelled by staff"
        if o.assigned:
            self._drop(self.robots[o.assigned], o)
        return f"cancelled {order_id}"

    def command(self, robot: str, command: str) -> str:
        """``pause``, ``resume`` or ``charge`` a robot; returns the message; ``ValueError`` if refused."""
        if robot not in self.robots:
            raise ValueError(f"unknown robot {robot!r}")
        r = self.robots[robot]
        if command == "pause":
            r.state, r.place, r.reason, r.route = "paused", "", "paused by staff", []
            self._give_back(r, f"{robot} paused")
            return f"{robot} paused"
        if command == "resume":
            r.reason = ""
            self._park(r)
            for o in self.orders:
                if o.state == "queued":
                    self._assign(o)
            return f"{robot} back in service"
        if command == "charge":
            if r.charger is None:
                raise ValueError(f"{robot} has no charger pose")
            r.state, r.place, r.reason = "to_charger", f"charger:{robot}", "sent by staff"
            self._give_back(r, f"{robot} went to charge")
            self._route(r, [r.charger])
            return f"{robot} goes to its charger"
        raise ValueError(f"unknown command {command!r} (pause, resume or charge)")

    def order(self, order_id: str) -> DemoOrder:
        """The order ``order_id`` (``ValueError`` if unknown)."""
        for o in self.orders:
            if o.id == order_id:
                return o
        raise ValueError(f"no order {order_id!r}")

    def _give_back(self, r: DemoRobot, why: str) -> None:
        for oid in list(r.orders):
            o = self.order(oid)
            o.state, o.assigned, o.reason = "queued", "", why
            self._drop(r, o)
        for o in self.orders:
            if o.state == "queued" and o.reason == why:
                self._assign(o)

    def _drop(self, r: DemoRobot, o: DemoOrder) -> None:
        if o.id in r.orders:
            r.orders.remove(o.id)
        needed = {t for oid in r.orders for t in self.order(oid).tables}
        r.stops = [s for s in r.stops if s in needed]
        if not r.orders and r.state in ("to_kitchen", "loading", "delivering", "serving"):
            self._park(r)

    def _park(self, r: DemoRobot) -> None:
        r.state, r.place = "parking", f"parking:{r.name}"
        self._route(r, [r.parking])

    # ------------------------------------------------------------------ time
    def step(self, dt: float) -> None:
        """Advance the play by ``dt`` s."""
        for r in self.robots.values():
            if r.state == "charging":
                r.battery = min(1.0, r.battery + 0.002 * dt)
                continue
            r.battery = max(0.0, r.battery - 0.0005 * dt * (self.speed > 0))
            if r.wait_s > 0:
                r.wait_s -= dt
                if r.wait_s <= 0:
                    self._leave_table(r)
                continue
            if not r.route or self.speed == 0:
                continue
            r.travelled = min(path_length(r.route), r.travelled + self.speed * dt)
            r.x, r.y, r.yaw = point_along(r.route, r.travelled)
            if r.travelled >= path_length(r.route) - ARRIVED_M:
                self._arrived(r)
        self._etas()

    def _arrived(self, r: DemoRobot) -> None:
        r.route = []
        if r.state == "to_kitchen":
            r.state, r.place = "delivering", r.stops[0] if r.stops else ""
            for oid in r.orders:
                self.order(oid).state = "on_the_way"
            self._route(r, [self.places[s] for s in r.stops])
        elif r.state == "delivering" and r.stops:
            r.state, r.place, r.wait_s = "serving", r.stops[0], SERVE_S
        elif r.state == "to_charger":
            r.state = "charging"
        elif r.state == "parking":
            r.state, r.place = "idle", ""

    def _leave_table(self, r: DemoRobot) -> None:
        served = r.stops.pop(0)
        for oid in list(r.orders):
            o = self.order(oid)
            if o.tables[-1] == served or not any(t in r.stops for t in o.tables):
                o.state, o.eta = "served", -1.0
                r.orders.remove(oid)
        if r.stops:
            r.state, r.place = "delivering", r.stops[0]
            self._route(r, [self.places[s] for s in r.stops])
        else:
            self._park(r)

    def remaining_path(self, r: DemoRobot) -> list[Point]:
        """The robot's route ahead of it (m, map frame), nearest point first; empty when not driving."""
        if not r.route:
            return []
        out, s = [], 0.0
        for a, b in zip(r.route, r.route[1:], strict=False):
            s += distance(a, b)
            if s > r.travelled:
                out.append(b)
        return out

    def _etas(self) -> None:
        speed = self.speed if self.speed > 0 else 0.3   # a still scene still shows planned ETAs
        for r in self.robots.values():
            here, t = (r.x, r.y), max(0.0, r.wait_s)
            if r.state == "to_kitchen":
                t += path_length([here, *self.remaining_path(r)]) / speed + 20.0
                here = self.places["kitchen"]
            times = {}
            for s in r.stops:
                t += distance(here, self.places[s]) * 1.3 / speed + SERVE_S
                here = self.places[s]
                times[s] = t
            for oid in r.orders:
                o = self.order(oid)
                o.eta = max((times.get(tb, 0.0) for tb in o.tables), default=-1.0)
        for o in self.orders:
            if o.state in ("queued", "served", "cancelled", "failed"):
                o.eta = -1.0
