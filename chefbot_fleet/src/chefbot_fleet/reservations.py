"""Who may drive into which single-lane zone (pure; times are float seconds of the caller's clock).

The rule, and why it cannot deadlock:

* A zone is granted to one robot at a time; robots asking for a held zone queue first-come
  first-served and wait at the zone's holding point, which lies outside every zone.
* A robot holds **at most one zone**, and asks for the next one only after it has released the
  one it holds (between two zones there is always a stretch wide enough for two robots: zones are
  separated by wide centre line, see :mod:`chefbot_fleet.zones`).

So no robot ever holds a zone while it waits for another: with no hold-and-wait, a cycle of
robots each waiting for the next one's zone cannot form (Coffman's condition), and FIFO queues
leave no waiting robot behind forever as long as every holder eventually leaves its zone.  A
holder that stops reporting (its stack died) loses its zone after ``timeout`` seconds; a robot
that finished its task must leave the zone (it drives to its parking pose) before it is idle.
"""
from __future__ import annotations

from collections import deque
from dataclasses import dataclass, field


class ReservationError(ValueError):
    """A request that breaks the rule (names the robot and the zones)."""


@dataclass
class ZoneTable:
    """The holder and the queue of every zone.  ``timeout`` (s): a robot not heard of for longer loses
    its zone and its places in queues (:meth:`expire`)."""

    timeout: float = 10.0
    holder: dict[int, str] = field(default_factory=dict)
    queues: dict[int, deque[str]] = field(default_factory=dict)
    seen: dict[str, float] = field(default_factory=dict)

    def held_by(self, robot: str) -> int:
        """The zone ``robot`` holds (0: none)."""
        return next((z for z, r in self.holder.items() if r == robot), 0)

    def request(self, robot: str, zone: int, now: float) -> bool:
        """``robot`` asks to drive into ``zone``: True when it holds it (now or already), False when it
        must wait (it is queued once).  ReservationError when it holds another zone: release it first."""
        if zone <= 0:
            raise ReservationError(f"{robot}: zone ids are >= 1, got {zone}")
        self.seen[robot] = now
        held = self.held_by(robot)
        if held == zone:
            return True
        if held:
            raise ReservationError(f"{robot} asks for zone {zone} while it holds zone {held}: a robot holds one zone "
                                   "at a time (release it when you leave it)")
        q = self.queues.setdefault(zone, deque())
        if robot not in q:
            q.append(robot)
        for other, queue in self.queues.items():   # one wait at a time: drop older requests elsewhere
            if other != zone and robot in queue:
                queue.remove(robot)
        if zone not in self.holder and q[0] == robot:
            q.popleft()
            self.holder[zone] = robot
            return True
        return False

    def take(self, robot: str, zone: int, now: float) -> bool:
        """``robot`` is inside ``zone`` already: it gets the zone at once when the zone is free, ahead of the
        robots queued for it (it cannot wait where it is).  False when another robot holds the zone."""
        self.seen[robot] = now
        if self.holder.get(zone, robot) != robot:
            return False
        if self.held_by(robot) not in (0, zone):
            raise ReservationError(f"{robot} takes zone {zone} while it holds zone {self.held_by(robot)}")
        self.holder[zone] = robot
        for queue in self.queues.values():
            if robot in queue:
                queue.remove(robot)
        return True

    def revoke(self, zone: int) -> str:
        """Take ``zone`` back from its holder, who has not entered it yet (another robot is inside): the
        holder goes to the head of the zone's queue.  Returns the former holder ('' when it was free)."""
        robot = self.holder.pop(zone, "")
        if robot:
            self.queues.setdefault(zone, deque()).appendleft(robot)
        return robot

    def withdraw(self, robot: str) -> None:
        """``robot`` no longer asks for any zone: it leaves every queue (a zone it holds stays its own).
        A queued robot that stopped asking must not stay at a queue's head and keep a free zone from the
        robots behind it."""
        for queue in self.queues.values():
            if robot in queue:
                queue.remove(robot)

    def release(self, robot: str, now: float) -> int:
        """``robot`` has left its zone (or gives up waiting): frees it and its places in queues; returns
        the zone it held (0: none).  The zone goes to the head of its queue at that robot's next request."""
        self.seen[robot] = now
        zone = self.held_by(robot)
        if zone:
            del self.holder[zone]
        for queue in self.queues.values():
            if robot in queue:
                queue.remove(robot)
        return zone

    def heartbeat(self, robot: str, now: float) -> None:
        """``robot`` is alive (keeps its zone and its place in a queue)."""
        self.seen[robot] = now

    def expire(self, now: float) -> list[tuple[str, int]]:
        """Release every robot not heard of for ``timeout`` s: (robot, zone it held) for each."""
        gone = [r for r, t in self.seen.items() if now - t > self.timeout]
        out = []
        for r in gone:
            out.append((r, self.release(r, now)))
            del self.seen[r]
        return out

    def waiting(self) -> dict[str, int]:
        """robot -> the zone it waits for."""
        return {r: z for z, q in self.queues.items() for r in q}

    def wait_edges(self) -> list[tuple[str, str]]:
        """(waiting robot, the robot it waits for): the wait-for graph."""
        return [(r, self.holder[z]) for r, z in self.waiting().items() if z in self.holder]
