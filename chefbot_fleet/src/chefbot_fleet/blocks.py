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

An **idle robot in the way** -- one without a goal, parked on another's path or goal, or inside a
single-lane zone another robot waits for -- never moves by itself.  It *makes room* when it has
stood on a robot's goal (the plan ends within the two radii plus ``clearance`` of it) or held the
zone a robot is held for for ``idle_confirm`` s (not at the first sight: two robots given goals at
once, one on the other's start, show one plan before the other), whether or not that robot has
stopped yet; when a robot with a goal has stood still for ``stall_time`` s with an idle one within
the first ``look_ahead`` m of its plan, too.  :func:`room_spot` picks the nearest free
spot it can reach -- past the other robots' bodies, not through them -- that is outside every zone
and clear of every other robot and of their plans, and the caller sends it there.  With no such spot
only because a robot waiting for a zone stands in the way out (at the mouth of the aisle the idle
one must leave), the caller tells that one to back off and asks again (:meth:`BlockDetector.retry`).

A robot **waiting for a zone in the way** -- held by the traffic rule where the robot coming out of
the zone must pass -- backs off (as a yielder of a mutual block) when that robot has stood still for
``stall_time`` s with it within the first ``look_ahead`` m of its plan.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage

from chefbot_navigation.robots_layer import clip_length, from_nearest


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
    room_margin: float = 0.10           # m kept free around a make-room spot beyond the robot's radius
    room_distance: float = 3.0          # m, the farthest make-room spot considered (straight line)
    idle_confirm: float = 2.0           # s an idle robot must stay on a robot's goal or in the zone it is held
                                        # for before it is sent off (a goal just given to it shows within this)

    def __post_init__(self) -> None:
        for name in ("stall_time", "stall_distance", "look_ahead", "cooldown", "robot_radius", "room_distance",
                     "idle_confirm"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name} must be > 0, got {getattr(self, name)}")
        if not self.clearance >= 0.0:
            raise ValueError(f"clearance must be >= 0 m, got {self.clearance}")
        if not self.room_margin >= 0.0:
            raise ValueError(f"room_margin must be >= 0 m, got {self.room_margin}")


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
    """A resolved block: ``yielder`` gives way to ``other`` (``idle``: the yielder has no goal and makes
    room, see :func:`room_spot`; otherwise it backs off -- ``waiting``: it was waiting for a zone)."""

    yielder: str
    other: str
    stalled_for: float                  # s both had stood still when it was caught (idle, waiting: ``other`` had)
    idle: bool = False
    waiting: bool = False               # the yielder waits for a zone, in the way of ``other``: it backs off
    where: str = "way"                  # idle: "way" (on its plan), "goal" (on its goal), "zone" (in the zone it
                                        # is held for)

    def text(self) -> str:
        """One line for logs and diagnostics."""
        if self.idle and self.where == "goal":
            return f"{self.yielder} stands idle on {self.other}'s goal: {self.yielder} makes room"
        if self.idle and self.where == "zone":
            return f"{self.yielder} stands idle in the zone {self.other} waits for: {self.yielder} makes room"
        if self.idle:
            return (f"{self.yielder} stands idle in {self.other}'s way ({self.other} stood still "
                    f"{self.stalled_for:.1f} s): {self.yielder} makes room")
        if self.waiting:
            return (f"{self.yielder} waits for a zone in {self.other}'s way ({self.other} stood still "
                    f"{self.stalled_for:.1f} s): {self.yielder} gives way")
        return (f"{self.yielder} and {self.other} blocked each other for {self.stalled_for:.1f} s: "
                f"{self.yielder} gives way")


def _densify(pts: np.ndarray, step: float = 0.05) -> np.ndarray:
    """The polyline ``pts`` ((N, 2) m) sampled every ``step`` m along each segment (sparse plans are
    judged along their length, not only at their vertices)."""
    seg = np.diff(pts, axis=0)
    if not len(seg):
        return pts
    n = np.maximum(np.ceil(np.hypot(seg[:, 0], seg[:, 1]) / step).astype(int), 1)
    return np.vstack([pts[:1]] + [pts[i] + np.linspace(0, 1, k + 1)[1:, None] * seg[i] for i, k in enumerate(n)])


def remaining(a: RobotView, look_ahead: float = math.inf) -> np.ndarray:
    """``a``'s plan from ``a`` on (from its point nearest ``a``), the first ``look_ahead`` m, densified."""
    rest = from_nearest(a.path, a.x, a.y)
    if len(rest) == 0:
        return np.zeros((0, 2))
    ahead = np.vstack(([[a.x, a.y]], rest))
    return _densify(clip_length(ahead, look_ahead) if math.isfinite(look_ahead) else ahead)


def in_the_way(a: RobotView, b: RobotView, look_ahead: float, clearance: float) -> bool:
    """Does the first ``look_ahead`` m of ``a``'s plan (from the point nearest ``a``) pass within the two
    radii plus ``clearance`` of ``b``?"""
    ahead = remaining(a, look_ahead)
    if len(ahead) == 0:
        return False
    return bool(np.min(np.hypot(ahead[:, 0] - b.x, ahead[:, 1] - b.y)) < a.radius + b.radius + clearance)


def on_its_goal(a: RobotView, b: RobotView, clearance: float) -> bool:
    """Does ``a``'s plan end within the two radii plus ``clearance`` of ``b`` (``b`` stands on ``a``'s goal)?"""
    if not len(a.path):
        return False
    gx, gy = a.path[-1]
    return math.hypot(gx - b.x, gy - b.y) < a.radius + b.radius + clearance


def room_spot(clearance: np.ndarray, info, keep_out: np.ndarray | None, me: RobotView, others: list[RobotView],
              cfg: BlockConfig, ghosts: frozenset[str] = frozenset()) -> tuple[float, float] | None:
    """Where the idle robot ``me`` makes room: the free spot nearest to it (straight line, within
    ``cfg.room_distance``) that

    * is ``me.radius`` + ``cfg.room_margin`` from the map's obstacles (``clearance``: (H, W) m from each
      cell to the nearest obstacle; ``info``: the map's GridInfo),
    * it can reach: connected to it through cells ``me.radius`` from obstacles and the two radii +
      ``cfg.clearance`` from every other robot but ``ghosts`` (robots about to move off; a robot already
      nearer than that leaves a way out from where ``me`` stands),
    * lies outside ``keep_out`` ((H, W) bool, e.g. where it would touch a single-lane zone),
    * is the two radii + ``cfg.clearance`` + ``cfg.room_margin`` from every other robot and from every
      point of their remaining plans.

    None when there is no such spot."""
    res = info.resolution
    h, w = clearance.shape
    row, col = (int(v) for v in info.world_to_cell(me.x, me.y))
    if not (0 <= row < h and 0 <= col < w):
        return None
    passable = clearance >= me.radius
    bodies = [o for o in others if o.name not in ghosts]
    if bodies:
        cx, cy = (np.asarray(v, float) for v in info.cell_to_world(*np.indices(clearance.shape)))
        for o in bodies:
            reach = min(me.radius + o.radius + cfg.clearance, math.hypot(me.x - o.x, me.y - o.y) - res)
            passable &= np.hypot(cx - o.x, cy - o.y) >= reach
    if not passable.any():
        return None
    pieces, _ = ndimage.label(passable, structure=np.ones((3, 3), bool))
    if not passable[row, col]:     # parked closer to an obstacle than the map's cells resolve: nearest passable
        _, (rr, cc) = ndimage.distance_transform_edt(~passable, return_indices=True)
        row, col = int(rr[row, col]), int(cc[row, col])
    ok = (pieces == pieces[row, col]) & (clearance >= me.radius + cfg.room_margin)
    if keep_out is not None:
        ok &= ~keep_out
    rows, cols = np.indices(clearance.shape)
    ok &= np.hypot(rows - row, cols - col) * res <= cfg.room_distance
    for o in others:
        pts = np.vstack(([[o.x, o.y]], remaining(o)))
        pr, pc = info.world_to_cell(pts[:, 0], pts[:, 1])
        pr, pc = np.asarray(pr, int), np.asarray(pc, int)
        on = (pr >= 0) & (pr < h) & (pc >= 0) & (pc < w)
        marks = np.zeros(clearance.shape, bool)
        marks[pr[on], pc[on]] = True
        if marks.any():
            ok &= ndimage.distance_transform_edt(~marks) * res >= me.radius + o.radius + cfg.clearance + cfg.room_margin
    if not ok.any():
        return None
    cand = np.argwhere(ok)
    mx, my = me.x, me.y
    cx, cy = info.cell_to_world(cand[:, 0], cand[:, 1])
    best = int(np.argmin(np.hypot(np.asarray(cx) - mx, np.asarray(cy) - my)))
    return float(np.asarray(cx)[best]), float(np.asarray(cy)[best])


class BlockDetector:
    """Feed it every robot at each decision (:meth:`update`); it returns the blocks to resolve now."""

    def __init__(self, cfg: BlockConfig) -> None:
        self.cfg = cfg
        self.history: dict[str, deque[tuple[float, float, float]]] = {}
        self.resolved: dict[frozenset[str], float] = {}
        self.last: Block | None = None          # the latest block resolved (diagnostics)
        self.count = 0                          # blocks resolved so far
        self.idle_seen: dict[tuple[str, str], float] = {}   # (idle, other) -> since when it is on its goal / zone

    def retry(self, block: Block, t: float, after: float) -> None:
        """``block`` could not be resolved at ``t`` (no spot to make room at yet): its pair is judged again
        ``after`` s from ``t`` instead of after the cooldown, and it is not counted."""
        self.resolved[frozenset((block.yielder, block.other))] = t - self.cfg.cooldown + after
        self.count -= 1

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

    def update(self, t: float, robots: list[RobotView], zone_waits: list[tuple[str, str]] = ()) -> list[Block]:
        """Record the robots' positions at ``t`` (s); the new blocks: mutual ones, each with its yielder
        (the robot later in ``robots``), robots waiting for a zone in a stalled robot's way (they back
        off) and idle robots on a robot's goal, in the zone it is held for or in a stalled robot's way
        (they make room).  ``zone_waits``: (waiting robot, holder) of the traffic rule's zones.  A robot
        yields at most once per call."""
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
        blocks: list[Block] = []
        yielded: set[str] = set()

        def judged(a: RobotView, b: RobotView) -> bool:
            """May the pair be judged now (not within its cooldown, ``a`` has not yielded in this call)?"""
            return a.name not in yielded and t - self.resolved.get(frozenset((a.name, b.name)), -math.inf) >= c.cooldown

        def resolve(block: Block) -> None:
            blocks.append(block)
            yielded.add(block.yielder)
            self.resolved[frozenset((block.yielder, block.other))] = t
            self.last = block
            self.count += 1

        # two robots with goals, each in the other's way: the later one backs off
        for i, a in enumerate(busy):
            for b in busy[i + 1:]:
                both = min(stalled[a.name], stalled[b.name])
                if judged(b, a) and both >= c.stall_time and in_the_way(a, b, c.look_ahead, c.clearance) \
                        and in_the_way(b, a, c.look_ahead, c.clearance):
                    resolve(Block(b.name, a.name, both))
        # a robot held by the traffic rule (waiting for a zone) standing in the way of a stalled robot --
        # the one coming out of that zone -- backs off: it is waiting anyway
        for b in busy:
            for a in robots:
                if a.held and len(a.path) and judged(a, b) and stalled[b.name] >= c.stall_time \
                        and in_the_way(b, a, c.look_ahead, c.clearance):
                    resolve(Block(a.name, b.name, stalled[b.name], waiting=True))
        # an idle robot on a robot's goal or in the zone it is held for (at once), or in the way of a
        # stalled one: it makes room
        idle = {r.name: r for r in robots if not len(r.path)}
        waits = {(r, h) for r, h in zone_waits if h in idle}
        seen: set[tuple[str, str]] = set()
        for b in robots:
            if not len(b.path):
                continue
            stood = self.stalled_for(b.name, t)
            for a in idle.values():
                zone = (b.name, a.name) in waits
                where = "zone" if zone and b.held else "goal" if on_its_goal(b, a, c.clearance) else ""
                if where:       # at once -- once it has stayed so idle_confirm s (two goals given together)
                    seen.add((a.name, b.name))
                    since = self.idle_seen.setdefault((a.name, b.name), t)
                    if judged(a, b) and t - since >= c.idle_confirm:
                        resolve(Block(a.name, b.name, stood, idle=True, where=where))
                    continue
                if not judged(a, b):
                    continue
                if stood >= c.stall_time and (zone or (not b.held and in_the_way(b, a, c.look_ahead, c.clearance))):
                    resolve(Block(a.name, b.name, stood, idle=True))
        self.idle_seen = {k: v for k, v in self.idle_seen.items() if k in seen}
        return blocks
