"""Mutual blocks: two robots standing still, each in the other's way, and which one gives way (pure).

The single-lane zones (chefbot_fleet.traffic) keep robots from meeting head-on where they cannot
pass.  Everywhere else robots plan round each other (move_base's robots layer); where that fails
-- a two-lane aisle pinched by a chair, a corner -- each plans *through* the other and waits
behind it, and without a tie-breaker both would wait until their patience runs out.

A pair is **mutually blocked** when, for ``stall_time`` s, both

* have a goal in the works and are not held by the traffic rule (a held robot waits on purpose),
* stood still: every pose of the window is within ``stall_distance`` of the current one,
* have the other in their way: the first ``look_ahead`` m of its remaining plan pass within the
  two robots' radii plus ``clearance`` of the other robot.

The detector then names one of them to give way: the one listed *later* (a fixed order, so the same
robot of a pair always yields and two robots never take turns backing off); it backs off along the way
it came (move_base's ``~give_way``), and the pair is not judged again for ``cooldown`` s.
Chains of three or more are resolved pair by pair.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from chefbot_navigation.robots_layer import clip_length


@dataclass(frozen=True)
class BlockConfig:
    """Mutual-block detection (m, s); the ``traffic`` node reads them from ``~blocks/<name>``."""

    enabled: bool = True                # detect mutual blocks and make one robot give way
    stall_time: float = 5.0             # s both robots stood still with the other in their way
    stall_distance: float = 0.05        # m: moving less than this over stall_time is standing still
    look_ahead: float = 1.5             # m of a robot's remaining plan checked for the other robot
    clearance: float = 0.10             # m added to the two robots' radii
    cooldown: float = 15.0              # s before the same pair is judged again
    robot_radius: float = 0.22          # m, the robots' circumscribed radius (ChefBot's URDF footprint: 0.223)

    def __post_init__(self) -> None:
        for name in ("stall_time", "stall_distance", "look_ahead", "cooldown", "robot_radius"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.clearance >= 0.0:
            raise ValueError(f"clearance must be >= 0 m, got {self.clearance}")


@dataclass
class RobotView:
    """What the detector needs of one robot now (map frame, m)."""

    name: str
    x: float
    y: float
    radius: float                       # circumscribed radius of its footprint
    path: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))   # remaining plan (empty: no goal)
    held: bool = False                  # the traffic rule makes it wait


@dataclass(frozen=True)
class Block:
    """A resolved mutual block: ``yielder`` gives way to ``other``."""

    yielder: str
    other: str
    stalled_for: float                  # s both had stood still when it was caught

    def text(self) -> str:
        """One line for logs and diagnostics."""
        return (f"{self.yielder} and {self.other} blocked each other for {self.stalled_for:.1f} s: "
                f"{self.yielder} gives way")


def in_the_way(a: RobotView, b: RobotView, look_ahead: float, clearance: float) -> bool:
    """Does the first ``look_ahead`` m of ``a``'s plan (from the point nearest ``a``) pass within the two
    radii plus ``clearance`` of ``b``?"""
    pts = np.asarray(a.path, dtype=float).reshape(-1, 2)
    if len(pts) == 0:
        return False
    start = int(np.argmin(np.hypot(pts[:, 0] - a.x, pts[:, 1] - a.y)))
    ahead = clip_length(np.vstack(([[a.x, a.y]], pts[start:])), look_ahead)
    # sample the segments every 5 cm so that sparse plans are judged along their length
    seg = np.diff(ahead, axis=0)
    n = np.maximum(np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / 0.05).astype(int), 1) if len(seg) else []
    dense = [ahead[:1]] + [ahead[i] + np.linspace(0, 1, k + 1)[1:, None] * seg[i] for i, k in enumerate(n)]
    dense = np.vstack(dense)
    return bool(np.min(np.hypot(dense[:, 0] - b.x, dense[:, 1] - b.y)) < a.radius + b.radius + clearance)


class BlockDetector:
    """Feed it every robot at each decision (:meth:`update`); it returns the blocks to resolve now."""

    def __init__(self, cfg: BlockConfig) -> None:
        self.cfg = cfg
        self.history: dict[str, deque[tuple[float, float, float]]] = {}
        self.resolved: dict[frozenset[str], float] = {}
        self.last: Block | None = None          # the latest block resolved (diagnostics)
        self.count = 0                          # blocks resolved so far

    def forget(self, name: str) -> None:
        """A robot is not heard of (no pose): its stall starts afresh when it is back."""
        self.history.pop(name, None)

    def stalled_for(self, name: str, t: float) -> float:
        """How long (s) the robot has stood still up to ``t`` (0 when it moves or is unknown)."""
        hist = self.history.get(name)
        if not hist:
            return 0.0
        _, x, y = hist[-1]
        since = t
        for ti, xi, yi in reversed(hist):
            if math.hypot(xi - x, yi - y) > self.cfg.stall_distance:
                break
            since = ti
        return t - since

    def update(self, t: float, robots: list[RobotView]) -> list[Block]:
        """Record the robots' positions at ``t`` (s); the new mutual blocks, each with its yielder (the
        robot later in ``robots``).  A robot yields at most once per call."""
        c = self.cfg
        for r in robots:
            hist = self.history.setdefault(r.name, deque())
            if hist and t < hist[-1][0]:           # time jumped back
                hist.clear()
            hist.append((t, r.x, r.y))
            while len(hist) > 2 and hist[1][0] <= t - 2.0 * c.stall_time:
                hist.popleft()
        busy = [r for r in robots if len(r.path) and not r.held]
        stalled = {r.name: self.stalled_for(r.name, t) for r in busy}
        blocks, yielded = [], set()
        for i, a in enumerate(busy):
            for b in busy[i + 1:]:
                pair = frozenset((a.name, b.name))
                if t - self.resolved.get(pair, -math.inf) < c.cooldown or b.name in yielded:
                    continue
                both = min(stalled[a.name], stalled[b.name])
                if both < c.stall_time:
                    continue
                if in_the_way(a, b, c.look_ahead, c.clearance) and in_the_way(b, a, c.look_ahead, c.clearance):
                    block = Block(b.name, a.name, both)
                    blocks.append(block)
                    yielded.add(b.name)
                    self.resolved[pair] = t
                    self.last = block
                    self.count += 1
        return blocks
