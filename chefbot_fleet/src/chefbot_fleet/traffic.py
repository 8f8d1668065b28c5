"""The fleet's traffic rule in the loop (pure): per robot and cycle, from its pose and its global plan,
which single-lane zone it needs, whether it may go on, and what it must be told.

Per robot, each cycle (:meth:`TrafficRule.update`):

1. a robot whose footprint touches a zone is *in* it: it takes the zone when it is free, ahead of any
   queue, and drives on — it cannot wait inside.  A zone granted to a robot that has not entered it
   yet, while another robot stands inside (a robot parked in the zone, or one whose pose was not yet
   known when the zone was granted), goes to the robot inside; the one outside waits again;
2. a zone it holds but neither touches nor has next on its plan is released -- when it has been in
   it, once its centre is ``hold_distance`` from the zone (the *apron*: as far out as a robot waiting
   for the zone stands), or at once when its plan asks for another zone.  A robot coming out of an
   aisle so keeps the aisle until it is out of the mouth, and the robot waiting there does not drive
   into it;
3. otherwise the first zone its remaining plan enters within ``lookahead`` m is asked for: granted,
   it drives on; refused, it drives on until its centre is ``hold_distance`` + ``hold_margin`` from
   the zone's area and then waits there (the hold's text names the zone and its holder).

Zones are far enough apart (:attr:`chefbot_fleet.zones.ZoneConfig.merge_distance`) that a robot
waiting for the next zone is clear of the last one, so no robot holds a zone while it waits: see
:mod:`chefbot_fleet.reservations` for why that leaves no deadlock.  A robot whose pose is unknown
is not heard of: after the table's timeout it loses its zone.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chefbot_common.geometry import Pose2D
from chefbot_fleet.reservations import ZoneTable
from chefbot_fleet.zones import ZoneConfig, ZoneMap
from chefbot_navigation.robots_layer import from_nearest


@dataclass(frozen=True)
class TrafficConfig:
    """How far ahead a robot books a zone, and when a silent robot loses its zone."""

    lookahead: float = 3.0             # [m] along the remaining plan: the next zone this close is asked for
    timeout: float = 10.0              # [s] a robot not heard of this long loses its zone (its stack died)

    def __post_init__(self) -> None:
        if not self.lookahead > 0:
            raise ValueError(f"lookahead must be > 0 m, got {self.lookahead}")
        if not self.timeout > 0:
            raise ValueError(f"timeout must be > 0 s, got {self.timeout}")


class ZoneGeometry:
    """Distances (m) from any map point to each zone's area (the zone map's distance fields)."""

    def __init__(self, zmap: ZoneMap) -> None:
        self.zmap = zmap
        self.dist = zmap.distance

    def _cell(self, x: float, y: float) -> tuple[int, int] | None:
        row, col = self.zmap.info.world_to_cell(x, y)
        h, w = self.zmap.labels.shape
        return (int(row), int(col)) if 0 <= row < h and 0 <= col < w else None

    def distance(self, zone: int, x: float, y: float) -> float:
        """From (x, y) to the zone's area (0 inside; inf off the map)."""
        cell = self._cell(x, y)
        return float(self.dist[zone][cell]) if cell is not None else float("inf")

    def touching(self, x: float, y: float, radius: float) -> list[int]:
        """The zones a disc of ``radius`` m at (x, y) overlaps, in id order."""
        cell = self._cell(x, y)
        if cell is None:
            return []
        return [z for z, d in self.dist.items() if d[cell] <= radius]

    def next_zone(self, plan: np.ndarray, x: float, y: float, radius: float, lookahead: float,
                  skip: int = 0) -> int:
        """The first zone other than ``skip`` a footprint of ``radius`` following ``plan`` ((N, 2) m)
        from its point nearest (x, y) would touch within ``lookahead`` m (0: none)."""
        ahead = from_nearest(plan, x, y)
        if len(ahead) == 0 or not self.dist:
            return 0
        travelled = 0.0
        prev = ahead[0]
        for p in ahead:
            travelled += float(np.hypot(*(p - prev)))
            prev = p
            if travelled > lookahead:
                break
            for z in self.touching(float(p[0]), float(p[1]), radius):
                if z != skip:
                    return z
        return 0


class TrafficRule:
    """The zone table and the per-robot decision (see the module docstring)."""

    def __init__(self, zmap: ZoneMap, zone_cfg: ZoneConfig | None = None, cfg: TrafficConfig | None = None) -> None:
        self.zcfg = zone_cfg or ZoneConfig()
        self.cfg = cfg or TrafficConfig()
        self.geom = ZoneGeometry(zmap)
        self.table = ZoneTable(timeout=self.cfg.timeout)
        self.inside: dict[str, list[int]] = {}      # robot -> the zones its footprint touched at its last update
        self.entered: dict[str, int] = {}           # robot -> the zone it holds and has been inside (coming out)

    def update(self, robot: str, pose: Pose2D | None, plan: np.ndarray | None, now: float) -> str:
        """One cycle for ``robot`` at ``pose`` (map frame; None: unknown) following ``plan`` (its remaining
        global plan, (N, 2) m; None or empty: no goal).  Returns why it must wait ('' = it may drive)."""
        if pose is None:
            return ""
        t = self.table
        t.heartbeat(robot, now)
        r = self.zcfg.robot_radius
        inside = self.geom.touching(pose.x, pose.y, r)
        self.inside[robot] = inside
        held = t.held_by(robot)
        ahead = self.geom.next_zone(plan, pose.x, pose.y, r, self.cfg.lookahead) if plan is not None else 0
        if held and held in inside:
            self.entered[robot] = held
        if held and held not in inside and held != ahead and \
                (ahead or self.entered.get(robot) != held or
                 self.geom.distance(held, pose.x, pose.y) >= self.zcfg.hold_distance):
            t.release(robot, now)
            self.entered.pop(robot, None)
            held = 0
        if inside:
            if held and held not in inside:     # in another zone already (zones closer than merge_distance
                t.release(robot, now)           # are one, so only with a map or params changed under it)
                self.entered.pop(robot, None)
                held = 0
            if not held:
                zone = inside[0]
                holder = t.holder.get(zone)
                if holder and zone not in self.inside.get(holder, []):
                    t.revoke(zone)              # granted to a robot still outside it: this one is in it
                t.take(robot, zone, now)        # in it already: it cannot wait here
            return ""
        if not ahead or held == ahead:
            t.withdraw(robot)                      # asks for nothing now: out of every queue
            return ""
        if held:               # booked a zone it no longer heads for first: give it back
            t.release(robot, now)
        if t.request(robot, ahead, now):
            return ""
        if self.geom.distance(ahead, pose.x, pose.y) <= self.zcfg.hold_distance + self.zcfg.hold_margin:
            return f"waiting for zone {ahead}, held by {t.holder.get(ahead, '?')}"
        return ""

    def keep_out(self) -> np.ndarray:
        """(H, W) bool: where a robot making room must not stop -- within ``hold_distance`` + ``hold_margin``
        of any zone: it would still hold the zone it came out of (the apron), or stand where robots wait."""
        return self.geom.zmap.keep_out(self.zcfg.hold_distance + self.zcfg.hold_margin)

    def expire(self, now: float) -> list[tuple[str, int]]:
        """Release every robot not heard of for ``timeout`` s: (robot, zone it held)."""
        gone = self.table.expire(now)
        for robot, _ in gone:
            self.inside.pop(robot, None)
            self.entered.pop(robot, None)
        return gone
