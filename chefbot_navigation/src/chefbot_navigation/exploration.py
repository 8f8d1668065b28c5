"""Frontier exploration (pure): where to drive next on a growing occupancy map.

A frontier cell is a free cell with an unknown 4-neighbour; frontier cells are
grouped 8-connected (``scipy.ndimage.label``).  For every group big enough, the
goal is the reachable free cell closest to the group's centroid that keeps
``clearance`` m from obstacles and lies within ``approach`` m of the group.
Reachability and the travel cost come from one geodesic distance transform
from the robot over the safe free cells (scikit-image's ``MCP_Geometric``).
The next goal minimises travel - ``gain_weight`` * frontier length; the goal
heading faces the frontier, so a narrow depth camera looks into the unknown.

Termination (what makes a live run end instead of chasing shadows):

* unknown *pockets* -- unknown regions enclosed by known cells (not touching the
  grid border) smaller than ``min_pocket_area`` m^2 (a table top's inside, the
  shadow behind a chair back) with at least ``pocket_min_occupied`` of their border
  occupied -- make no frontier (open floor nobody looked at does);
* a :class:`Blacklist` of frontier *cells*: a frontier whose goal failed, timed
  out or made no progress, or that was visited (goal reached, look-around done)
  and is still there, is given up; later frontiers with at least
  ``blacklist_share`` of their cells within ``blacklist_radius`` of given-up
  cells are skipped;
* :class:`ProgressWatch` (sim seconds): a goal that brings the robot no
  ``min_gain`` nearer and the map no new area for ``timeout`` s is stalled; the
  whole run stops when the known area grows by less than ``stall_area`` in
  ``stall_timeout``;
* :func:`final_line` says why the run ended and what was left.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.spatial import cKDTree
from skimage.graph import MCP_Geometric

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import FREE, UNKNOWN, OccupancyMap


@dataclass
class ExploreConfig:
    """Goal selection parameters (m unless stated)."""

    clearance: float = 0.5           # goal distance from any occupied cell
    robot_radius: float = 0.2        # travel corridor distance from occupied cells
    approach: float = 1.0            # goal at most this far from its frontier
    min_frontier: float = 0.3        # frontier length (m, cells * resolution) worth a visit
    gain_weight: float = 1.0         # m of travel a metre of frontier is worth
    blacklist_radius: float = 0.5    # m, given-up frontier cells cover later frontier cells this close
    blacklist_share: float = 0.5     # [fraction] a frontier with this share (0..1] of its cells covered is given up
    min_pocket_area: float = 2.0     # m^2, enclosed unknown regions smaller than this are not explored ...
    pocket_min_occupied: float = 0.1  # [fraction] ... when at least this share (0..1) of their border is occupied
                                      # (a table top, a shadow behind a chair); a pocket of open floor (free
                                      # border) is explored
    view_distance: float = 1.0       # m, preferred goal distance from the frontier, with line of sight (0: nearest
                                     # to the frontier's centroid); the depth camera sees nothing nearer than ~0.45 m
    camera_fov: float = 1.01         # rad, the depth camera's horizontal field of view (58 deg)
    view_clear: float = 0.6          # m, "camera not blind": known free space this far ahead of the goal heading,
                                     # all across camera_fov (range_min 0.45 m + a margin; 0: rule off)
    spin_clear: float = 0.45         # m, and known free this far out (the camera's range_min) in ...
    spin_open_share: float = 0.5     # [fraction] ... at least this share (0..1) of all directions, for the
                                     # look-around spin (0: off)

    def __post_init__(self) -> None:
        if not 0 < self.blacklist_share <= 1:
            raise ValueError(f"blacklist_share must be in (0, 1], got {self.blacklist_share}")
        if self.min_pocket_area < 0:
            raise ValueError(f"min_pocket_area must be >= 0 m^2, got {self.min_pocket_area}")
        if not 0 <= self.pocket_min_occupied <= 1:
            raise ValueError(f"pocket_min_occupied must be in [0, 1], got {self.pocket_min_occupied}")
        for name in ("view_distance", "view_clear", "spin_clear"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0 m, got {getattr(self, name)}")
        if not 0 < self.camera_fov <= 2 * math.pi:
            raise ValueError(f"camera_fov must be in (0, 2 pi] rad, got {self.camera_fov}")
        if not 0 <= self.spin_open_share <= 1:
            raise ValueError(f"spin_open_share must be in [0, 1], got {self.spin_open_share}")
        for name in ("clearance", "robot_radius", "approach", "min_frontier", "blacklist_radius"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0 m, got {getattr(self, name)}")
        if self.gain_weight < 0:
            raise ValueError(f"gain_weight must be >= 0, got {self.gain_weight}")


@dataclass(frozen=True)
class ExploreNodeParams:
    """The explore node's own parameters (s, rad/s)."""

    mode: str = "frontier"              # frontier | waypoints
    map_frame: str = "map"              # frame of the goals sent to move_base and of the robot pose from tf
    base_frame: str = "base_footprint"  # robot frame looked up in tf (map_frame -> base_frame)
    goal_timeout: float = 60.0          # s (sim) per goal
    max_duration: float = 900.0         # s (sim) for the whole run
    spin_speed: float = 0.8             # rad/s of the look-around spins (0: none)
    recheck_period: float = 2.0         # s, is the current goal's frontier still open?
    progress_timeout: float = 20.0      # s (sim) without progress (nearer the goal or new area) cancel a goal
    progress_distance: float = 0.25     # m nearer the goal that count as progress
    progress_area: float = 0.5          # m^2 of new known area that count as progress
    stall_timeout: float = 150.0        # s (sim): the run stops when the known area grows less than ...
    stall_area: float = 2.0             # m^2 in stall_timeout
    max_stuck: int = 3                  # goals in a row without the robot moving progress_distance: stop (not done)

    def __post_init__(self) -> None:
        if self.mode not in ("frontier", "waypoints"):
            raise ValueError(f"mode must be 'frontier' or 'waypoints', got {self.mode!r}")
        for name in ("goal_timeout", "max_duration", "recheck_period", "progress_timeout", "stall_timeout"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0 s, got {getattr(self, name)}")
        if self.max_stuck < 1:
            raise ValueError(f"max_stuck must be >= 1, got {self.max_stuck}")
        for name in ("spin_speed", "progress_distance", "progress_area", "stall_area"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)}")


@dataclass
class Frontier:
    """A frontier group: aim point (m; its centroid, or with ``view_distance`` > 0 the frontier cell nearest
    the centroid), length (m), goal pose, travel cost (m), cells (N x 2 world m)."""

    centroid: tuple[float, float]
    length: float
    goal: Pose2D
    travel: float
    cells: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))


@dataclass
class FrontierScan:
    """All frontier groups of one map: reachable ones best first, and how many were left out why."""

    frontiers: list[Frontier]
    blacklisted: int = 0       # mostly given-up cells
    unreachable: int = 0       # no safe reachable goal within `approach`
    small: int = 0             # shorter than min_frontier
    blind: int = 0             # reachable goals, but none where the camera would see (camera_view_ok)

    @property
    def left(self) -> int:
        """Frontier groups still in the map (worth a visit or not)."""
        return len(self.frontiers) + self.blacklisted + self.unreachable + self.small + self.blind


class Blacklist:
    """Given-up frontier cells (world m), kept in world coordinates so a growing map does not shift them."""

    def __init__(self, radius: float, share: float) -> None:
        self.radius, self.share = radius, share
        self.points = np.empty((0, 2))
        self.reasons: dict[str, int] = {}
        self._tree: cKDTree | None = None

    def add(self, frontier: Frontier, reason: str) -> None:
        """Give up ``frontier`` (``reason``: failed, stalled, visited, ... counted for the final line)."""
        pts = frontier.cells if len(frontier.cells) else np.array([frontier.centroid], dtype=float)
        self.points = np.vstack([self.points, pts])
        self.reasons[reason] = self.reasons.get(reason, 0) + 1
        self._tree = cKDTree(self.points)

    def covers(self, cells: np.ndarray) -> bool:
        """Are at least ``share`` of ``cells`` (N x 2, m) within ``radius`` of given-up cells?"""
        if self._tree is None or len(cells) == 0:
            return False
        d, _ = self._tree.query(cells, distance_upper_bound=self.radius)
        return float(np.mean(np.isfinite(d))) >= self.share

    def __len__(self) -> int:
        return sum(self.reasons.values())


class ProgressWatch:
    """Stalled when a value has not risen by ``min_gain`` within ``timeout`` s (sim time)."""

    def __init__(self, timeout: float, min_gain: float) -> None:
        self.timeout, self.min_gain = timeout, min_gain
        self.t_best: float | None = None
        self.best = -math.inf

    def reset(self, t: float, value: float) -> None:
        """Start watching anew from ``value`` at time ``t`` (s)."""
        self.t_best, self.best = t, value

    def update(self, t: float, value: float) -> bool:
        """Feed the value at time ``t`` (s); True when stalled. Time going backwards restarts the watch."""
        if self.t_best is None or t < self.t_best or value >= self.best + self.min_gain:
            self.reset(t, value)
            return False
        return t - self.t_best >= self.timeout


class GoalWatch:
    """A goal makes no progress when for ``progress_timeout`` s the robot came no ``progress_distance`` m
    nearer to it *and* the map gained no ``progress_area`` m^2 (sim time; see ExploreNodeParams)."""

    def __init__(self, p: ExploreNodeParams) -> None:
        self.near = ProgressWatch(p.progress_timeout, p.progress_distance)
        self.area = ProgressWatch(p.progress_timeout, p.progress_area)

    def update(self, t: float, distance: float, known: float) -> bool:
        """Feed the time (s), distance to the goal (m) and known area (m^2); True when stalled."""
        near = self.near.update(t, -distance)
        return self.area.update(t, known) and near


POCKET_MIN_OCCUPIED = 0.1   # ExploreConfig.pocket_min_occupied's default, for the progress lines


def open_unknown(occ: OccupancyMap, min_pocket_area: float, min_occupied: float = POCKET_MIN_OCCUPIED) -> np.ndarray:
    """Unknown cells worth exploring: all unknown except enclosed pockets (not touching the grid border)
    smaller than ``min_pocket_area`` m^2 with at least ``min_occupied`` of their border cells occupied.
    A pocket whose border is (nearly) all free is floor nobody looked at, not a table top or a shadow:
    it stays (one of 1.4 m^2 held the table_5 delivery pose after a hotel exploration)."""
    unk = occ.data == UNKNOWN
    if min_pocket_area <= 0 or not unk.any():
        return unk
    labels, n = ndimage.label(unk)
    sizes = np.bincount(labels.ravel(), minlength=n + 1) * occ.info.resolution ** 2
    border = np.unique(np.concatenate([labels[0], labels[-1], labels[:, 0], labels[:, -1]]))
    keep = sizes >= min_pocket_area
    if min_occupied > 0:
        # border ring of each pocket: known cells with a pocket cell among their 4-neighbours
        near = ndimage.grey_dilation(labels, footprint=ndimage.generate_binary_structure(2, 1))
        ring = (near > 0) & ~unk
        cells = np.bincount(near[ring], minlength=n + 1)
        occupied = np.bincount(near[ring], weights=(occ.data[ring] > 50).astype(float), minlength=n + 1)
        keep |= (cells > 0) & (occupied < min_occupied * cells)
    keep[border] = True
    keep[0] = False
    return keep[labels]


def frontier_mask(occ: OccupancyMap, min_pocket_area: float = 0.0,
                  min_occupied: float = POCKET_MIN_OCCUPIED) -> np.ndarray:
    """Boolean mask of free cells with an unknown 4-neighbour (outside pockets, see :func:`open_unknown`)."""
    free = occ.data == FREE
    unk = open_unknown(occ, min_pocket_area, min_occupied)
    near = np.zeros_like(unk)
    near[1:, :] |= unk[:-1, :]
    near[:-1, :] |= unk[1:, :]
    near[:, 1:] |= unk[:, :-1]
    near[:, :-1] |= unk[:, 1:]
    return free & near


def line_of_sight(occ: OccupancyMap, x: np.ndarray, y: np.ndarray, tx: float, ty: float) -> np.ndarray:
    """For each start (x, y) (m): does the straight line to (tx, ty) cross no occupied cell (before the target)?"""
    x, y = np.asarray(x, dtype=float), np.asarray(y, dtype=float)
    n = max(2, int(np.ceil(np.hypot(x - tx, y - ty).max(initial=0.0) / (0.5 * occ.info.resolution))) + 1)
    f = np.linspace(0.0, 1.0, n)[None, :-1]                  # the target cell itself may be anything
    px, py = x[:, None] + (tx - x[:, None]) * f, y[:, None] + (ty - y[:, None]) * f
    r, c = occ.info.world_to_cell(px, py)
    inside = occ.info.inside(r, c)
    blocked = np.zeros(px.shape, dtype=bool)
    blocked[inside] = occ.data[r[inside], c[inside]] > 50
    return ~blocked.any(axis=1)


def rays_free(occ: OccupancyMap, x: np.ndarray, y: np.ndarray, angles: np.ndarray, reach: float) -> np.ndarray:
    """(N, K) bool: is every cell from (x[i], y[i]) (m) out to ``reach`` m along heading ``angles[i, k]`` (rad)
    known FREE (not occupied, not unknown, inside the map)?  Sampled every half cell."""
    x, y = np.asarray(x, dtype=float)[:, None, None], np.asarray(y, dtype=float)[:, None, None]
    a = np.asarray(angles, dtype=float)[:, :, None]
    steps = np.linspace(0.0, reach, max(2, int(np.ceil(reach / (0.5 * occ.info.resolution))) + 1))[None, None, :]
    r, c = occ.info.world_to_cell(x + np.cos(a) * steps, y + np.sin(a) * steps)
    inside = occ.info.inside(r, c)
    free = np.zeros(inside.shape, dtype=bool)
    free[inside] = occ.data[r[inside], c[inside]] == FREE
    return free.all(axis=2)


def camera_view_ok(occ: OccupancyMap, x: np.ndarray, y: np.ndarray, yaw: np.ndarray, cfg: ExploreConfig) -> np.ndarray:
    """The "camera not blind" rule (bool per goal (x, y, yaw), m/rad): the depth camera sees nothing nearer than its
    range_min (0.45 m), so a goal is only worth parking at when (1) the whole field of view (``camera_fov``)
    is known free ``view_clear`` m ahead of the goal heading, and (2) for the look-around spin, at least
    ``spin_open_share`` of all directions are known free ``spin_clear`` m out.  An unknown cell counts as
    blocked: it may hide the pillar or wall that would leave the camera (and SLAM's scan matcher) blind,
    as in the 0.8 m gap between a pillar and a wall where SLAM diverged (chefbot_navigation/README.md)."""
    x, y, yaw = (np.atleast_1d(np.asarray(v, dtype=float)) for v in (x, y, yaw))
    ok = np.ones(len(x), dtype=bool)
    if len(x) == 0:
        return ok
    if cfg.view_clear > 0:
        cone = np.linspace(-cfg.camera_fov / 2, cfg.camera_fov / 2, max(3, int(np.ceil(cfg.camera_fov / 0.1)) + 1))
        ok &= rays_free(occ, x, y, yaw[:, None] + cone[None, :], cfg.view_clear).all(axis=1)
    if cfg.spin_open_share > 0 and cfg.spin_clear > 0:
        around = np.linspace(-math.pi, math.pi, 24, endpoint=False)
        share = rays_free(occ, x, y, np.broadcast_to(around, (len(x), len(around))), cfg.spin_clear).mean(axis=1)
        ok &= share >= cfg.spin_open_share
    return ok


def goal_headings(gx: np.ndarray, gy: np.ndarray, aim: tuple[float, float], robot: Pose2D) -> np.ndarray:
    """Heading (rad) of goals at (gx, gy) (m): facing ``aim`` (the frontier), or, for a goal within 0.3 m of
    it, on along the way from the robot (from the known side into the unknown)."""
    gx, gy = np.asarray(gx, dtype=float), np.asarray(gy, dtype=float)
    face = np.arctan2(aim[1] - gy, aim[0] - gx)
    along = np.where(np.hypot(gx - robot.x, gy - robot.y) > 1e-6, np.arctan2(gy - robot.y, gx - robot.x), robot.yaw)
    return np.where(np.hypot(aim[0] - gx, aim[1] - gy) > 0.3, face, along)


def find_frontiers(occ: OccupancyMap, robot: Pose2D, cfg: ExploreConfig,
                   blacklist: Blacklist | None = None) -> list[Frontier]:
    """Reachable frontier groups with their goals, best first (see the module docstring)."""
    return scan_frontiers(occ, robot, cfg, blacklist).frontiers


def scan_frontiers(occ: OccupancyMap, robot: Pose2D, cfg: ExploreConfig,
                   blacklist: Blacklist | None = None) -> FrontierScan:
    """All frontier groups: the reachable, not given-up ones with goals (best first) and the counts of the rest."""
    info, res = occ.info, occ.info.resolution
    occupied = occ.data > 50
    dist = ndimage.distance_transform_edt(~occupied) * res if occupied.any() else np.full(occ.data.shape, 1e9)
    free = occ.data == FREE
    passable = free & (dist >= cfg.robot_radius)
    r0, c0 = info.world_to_cell(robot.x, robot.y)
    if not info.inside(r0, c0):
        raise ValueError(f"robot ({robot.x:.2f}, {robot.y:.2f}) m is outside the map")
    # the robot's own cell may be unknown or close to a wall: let it start from there
    passable[max(r0 - 2, 0):r0 + 3, max(c0 - 2, 0):c0 + 3] |= occ.data[max(r0 - 2, 0):r0 + 3,
                                                                        max(c0 - 2, 0):c0 + 3] != 100
    cost = np.where(passable, 1.0, np.inf)
    travel, _ = MCP_Geometric(cost).find_costs([(int(r0), int(c0))])
    travel = travel * res
    labels, n = ndimage.label(frontier_mask(occ, cfg.min_pocket_area, cfg.pocket_min_occupied),
                              structure=np.ones((3, 3)))
    scan = FrontierScan([])
    if n == 0:
        return scan
    goal_ok = passable & (dist >= cfg.clearance) & np.isfinite(travel)
    gr, gc = np.nonzero(goal_ok)
    gx, gy = info.cell_to_world(gr, gc)
    for lab, sl in enumerate(ndimage.find_objects(labels), start=1):
        rr, cc = np.nonzero(labels[sl] == lab)
        length = len(rr) * res
        if length < cfg.min_frontier:
            scan.small += 1
            continue
        fx, fy = info.cell_to_world(rr + sl[0].start, cc + sl[1].start)
        cells = np.column_stack([fx, fy])
        if blacklist is not None and blacklist.covers(cells):
            scan.blacklisted += 1
            continue
        cx, cy = float(fx.mean()), float(fy.mean())
        # candidate goals near this frontier: within `approach` of its nearest frontier cell
        d_front = np.full(len(gx), np.inf)
        near = (np.abs(gx - cx) < cfg.approach + length) & (np.abs(gy - cy) < cfg.approach + length)
        if not near.any():
            scan.unreachable += 1
            continue
        idx = np.nonzero(near)[0]
        step = max(1, len(fx) // 50)
        d = np.hypot(gx[idx, None] - fx[None, ::step], gy[idx, None] - fy[None, ::step]).min(axis=1)
        d_front[idx] = d
        cand = d_front <= cfg.approach
        if not cand.any():
            scan.unreachable += 1
            continue
        idx = np.nonzero(cand)[0]
        # aim at the frontier cell nearest its centroid; prefer goals about view_distance from it that see it
        j = int(np.argmin(np.hypot(fx - cx, fy - cy)))
        tx, ty = float(fx[j]), float(fy[j])
        score = np.hypot(gx[idx] - cx, gy[idx] - cy)
        if cfg.view_distance > 0:
            d = np.maximum(np.hypot(gx[idx] - tx, gy[idx] - ty), 1e-9)
            # looking at the target must look on into the unknown (not along the frontier)
            br, bc = info.world_to_cell(tx + (tx - gx[idx]) / d * 2 * res, ty + (ty - gy[idx]) / d * 2 * res)
            ok = info.inside(br, bc)
            into = np.zeros(len(idx), dtype=bool)
            into[ok] = occ.data[br[ok], bc[ok]] == UNKNOWN
            score = np.abs(d - cfg.view_distance) + np.where(into, 0.0, cfg.view_distance)
            seen = line_of_sight(occ, gx[idx], gy[idx], tx, ty)
            if seen.any():
                idx, score = idx[seen], score[seen]
        if cfg.view_distance > 0:
            cx, cy = tx, ty
        # face the frontier; a goal on the frontier itself faces on along the way it was reached
        yaws = goal_headings(gx[idx], gy[idx], (cx, cy), robot)
        seeing = camera_view_ok(occ, gx[idx], gy[idx], yaws, cfg)
        if not seeing.any():
            scan.blind += 1
            continue
        best = int(np.argmin(np.where(seeing, score, np.inf)))
        k, yaw = idx[best], float(yaws[best])
        x, y = float(gx[k]), float(gy[k])
        scan.frontiers.append(Frontier((cx, cy), length, Pose2D(x, y, yaw), float(travel[gr[k], gc[k]]), cells))
    scan.frontiers.sort(key=lambda f: f.travel - cfg.gain_weight * f.length)
    return scan


def known_area(occ: OccupancyMap) -> tuple[float, float]:
    """(known m^2, free m^2) of the map."""
    a = occ.info.resolution ** 2
    return float((occ.data != UNKNOWN).sum() * a), float((occ.data == FREE).sum() * a)


def closed_share(occ: OccupancyMap, min_pocket_area: float = 0.0) -> float:
    """Share (0..1) of the free area's outline that is closed: free cells bordering unknown or occupied cells
    that border occupied ones.  1.0 = the known free space is walled in everywhere (the map is complete)."""
    free = occ.data == FREE
    occupied = occ.data > 50
    front = frontier_mask(occ, min_pocket_area)
    walled = free & ndimage.binary_dilation(occupied, structure=np.ones((3, 3))) & ~front
    n_front, n_wall = int(front.sum()), int(walled.sum())
    return n_wall / (n_wall + n_front) if n_wall + n_front else 0.0


def progress(occ: OccupancyMap, n_frontiers: int, elapsed: float, min_pocket_area: float = 0.0) -> str:
    """One progress line: known and free area (m^2), share of the outline closed, frontiers left, elapsed (s)."""
    known, free = known_area(occ)
    closed = 100 * closed_share(occ, min_pocket_area)
    return (f"explore: known {known:.1f} m^2, free {free:.1f} m^2, outline {closed:.1f} % closed, "
            f"{n_frontiers} frontiers left, elapsed {elapsed:.0f} s")


def final_line(occ: OccupancyMap, scan: FrontierScan, blacklist: Blacklist, elapsed: float, reason: str,
               min_pocket_area: float = 0.0) -> str:
    """The run's last line: why it ended, areas, outline closed, sim time, what was left and why."""
    given_up = ", ".join(f"{n} {r}" for r, n in sorted(blacklist.reasons.items())) or "none"
    state = progress(occ, scan.left, elapsed, min_pocket_area).removeprefix("explore: ")
    return (f"explore: finished ({reason}) after {elapsed:.0f} s sim time; {state}"
            f" [{len(scan.frontiers)} open, {scan.blacklisted} given up, {scan.unreachable} unreachable, "
            f"{scan.blind} blind, {scan.small} too small]; goals given up: {given_up}")


def stop_reason(scan: FrontierScan, elapsed: float, known: float, stall: ProgressWatch,
                p: ExploreNodeParams, stuck: int = 0) -> tuple[str, bool] | None:
    """Why the run ends now, and whether that counts as done (True) or given up (False); None: go on.

    ``elapsed`` s since the start, ``known`` m^2; ``stall`` watches the known area over ``stall_timeout``;
    ``stuck``: goals in a row that ended "stuck" (see :func:`goal_outcome`)."""
    if p.mode == "waypoints":
        return "route driven", True
    if stuck >= p.max_stuck:
        return f"robot stuck: {stuck} goals in a row without moving {p.progress_distance:g} m", False
    if not scan.frontiers:
        return "no reachable frontier left", True
    if stall.update(elapsed, known):
        return f"known area grew < {p.stall_area:g} m^2 in {p.stall_timeout:.0f} s", True
    if elapsed > p.max_duration:
        return f"max_duration {p.max_duration:.0f} s reached", False
    return None


def goal_outcome(outcome: str, moved: float, p: ExploreNodeParams) -> str:
    """A goal that timed out or made no progress while the robot moved less than ``progress_distance`` m
    (``moved``: farthest distance from where the goal started) is "stuck": the robot is wedged or a
    phantom obstacle blocks it, which says nothing about the frontier.  Other outcomes pass unchanged."""
    return "stuck" if outcome in ("no progress", "timeout") and moved < p.progress_distance else outcome


def record_visit(blacklist: Blacklist, frontier: Frontier, outcome: str) -> bool:
    """Give ``frontier`` up after a goal ``outcome`` (succeeded, cleared, stuck, failed, timeout, no progress).

    A reached goal (the look-around done) leaves what remains of its frontier unobservable from there;
    ``cleared`` (mapped on the way) and ``stuck`` give nothing up.  True when it was given up for a failure."""
    if outcome in ("cleared", "stuck"):
        return False
    blacklist.add(frontier, "visited" if outcome == "succeeded" else outcome)
    return outcome != "succeeded"


def still_open(centroid: tuple[float, float], frontiers: list[Frontier], radius: float = 0.5) -> bool:
    """Is a frontier with its centroid within ``radius`` m of ``centroid`` still among ``frontiers``?"""
    return any(math.hypot(f.centroid[0] - centroid[0], f.centroid[1] - centroid[1]) < radius for f in frontiers)
