"""Global planners over a costmap (pure; scikit-image's MCP does the Dijkstra).

Interface: ``GlobalPlanner.plan(costmap, start, goal) -> Plan`` (world
coordinates in m), raising :class:`PlanningError` with a reason and a
``kind`` the caller can act on.  Implementations, chosen by name with
:func:`make_planner`:

* ``dijkstra``: exact minimum-cost path on the 8-connected grid
  (``skimage.graph.MCP_Geometric``: edge cost = step length x mean of the two
  cell costs), then string-pulling and resampling;
* ``hierarchical``: the same on a 5x coarser grid first (mean of the cell
  costs, blocked cells counted at a high penalty), then exact Dijkstra at
  full resolution on only the cells of a corridor around the coarse path
  (scipy.sparse.csgraph; falls back to ``dijkstra`` when the corridor has
  no path).  Identical to
  ``dijkstra`` on maps up to ``full_search_cells`` cells.

Cell traversal cost = neutral_cost + cost_factor * cost / 252 for costs below
253 (like NavFn's COST_NEUTRAL + COST_FACTOR * cost); inscribed, lethal and
(unless ``allow_unknown``) unknown cells are impassable.
"""
from __future__ import annotations

import math
import threading
import time
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra
from skimage.graph import MCP_Geometric

from chefbot_navigation.costmap import INSCRIBED, LETHAL, NO_INFORMATION, Costmap


class PlanningError(RuntimeError):
    """No plan; ``kind`` is one of start_off_map, goal_off_map, goal_in_obstacle,
    goal_too_close, goal_unknown, no_path."""

    def __init__(self, kind: str, reason: str) -> None:
        super().__init__(reason)
        self.kind = kind
        self.reason = reason


@dataclass(frozen=True)
class PlannerParams:
    """Planner tunables (names as NavFn/global_planner's where the meaning matches)."""

    neutral_cost: float = 1.0          # cost of one free cell per cell length
    cost_factor: float = 3.0           # extra cost of a cell of cost 252 (near an obstacle)
    allow_unknown: bool = False        # plan through unknown cells (at the cost of a 252 cell)
    smooth: bool = True                # string-pull the grid path
    path_resolution: float = 0.05      # m, spacing of the published path
    full_search_cells: int = 250_000   # [cells] hierarchical: plan exactly below this many cells
    coarse_factor: int = 5             # [cells] hierarchical: cells per coarse cell (per axis)
    corridor_margin: int = 3           # hierarchical: coarse cells around the coarse path
    coarse_crop: float = 0.2           # hierarchical: coarse search box margin, x start-goal distance (0 = whole map)

    def __post_init__(self) -> None:
        if not self.neutral_cost > 0.0:
            raise ValueError(f"neutral_cost must be > 0, got {self.neutral_cost}")
        if not self.cost_factor >= 0.0:
            raise ValueError(f"cost_factor must be >= 0, got {self.cost_factor}")
        if not self.path_resolution > 0.0:
            raise ValueError(f"path_resolution must be > 0 m, got {self.path_resolution}")
        if self.coarse_factor < 2 or self.corridor_margin < 1:
            raise ValueError("coarse_factor must be >= 2 and corridor_margin >= 1")
        if not (math.isfinite(self.coarse_crop) and self.coarse_crop >= 0.0):
            raise ValueError(f"coarse_crop must be a finite number >= 0, got {self.coarse_crop}")


@dataclass
class Plan:
    """A planned path: ``points`` (N, 2) m in the costmap frame, ``cells`` the raw grid path
    (M, 2) (row, col), ``cost`` the grid path's cost (cell-cost x cell lengths), ``seconds``
    the planning time."""

    points: np.ndarray
    cells: np.ndarray
    cost: float
    seconds: float


class GlobalPlanner(Protocol):
    """What move_base needs from a global planner."""

    def plan(self, costmap: Costmap, start: tuple[float, float], goal: tuple[float, float]) -> Plan:
        """Path from start to goal (m, costmap frame) or :class:`PlanningError`."""
        ...


def cost_lut(params: PlannerParams) -> np.ndarray:
    """Traversal cost (float64) for each of the 256 costmap values, ``inf`` where impassable."""
    lut = params.neutral_cost + params.cost_factor * np.minimum(np.arange(256), 252) / 252.0
    lut[INSCRIBED:] = np.inf
    if params.allow_unknown:
        lut[NO_INFORMATION] = params.neutral_cost + params.cost_factor
    return lut


def cell_costs(cost: np.ndarray, params: PlannerParams) -> np.ndarray:
    """Traversal cost per cell (float64), ``inf`` where impassable."""
    return cost_lut(params)[cost]


def path_cost(cells: np.ndarray, costs: np.ndarray) -> float:
    """Cost of a grid path under MCP_Geometric's edge model (length x mean of cell costs)."""
    cells = np.asarray(cells)
    c = costs[cells[:, 0], cells[:, 1]]
    steps = np.hypot(*np.diff(cells, axis=0).T)
    return float(np.sum(steps * 0.5 * (c[:-1] + c[1:])))


def _check_endpoints(costmap: Costmap, start: tuple[float, float], goal: tuple[float, float],
                     params: PlannerParams) -> tuple[tuple[int, int], tuple[int, int]]:
    info = costmap.info
    sr, sc = (int(v) for v in info.world_to_cell(*start))
    gr, gc = (int(v) for v in info.world_to_cell(*goal))
    if not info.inside(np.array(sr), np.array(sc)):
        raise PlanningError("start_off_map", f"robot position ({start[0]:.4g}, {start[1]:.4g}) is off the map")
    if not info.inside(np.array(gr), np.array(gc)):
        raise PlanningError("goal_off_map", f"goal ({goal[0]:.4g}, {goal[1]:.4g}) is off the map")
    g = int(costmap.cost[gr, gc])
    where = f"goal ({goal[0]:.4g}, {goal[1]:.4g})"
    if g == LETHAL:
        raise PlanningError("goal_in_obstacle", f"{where} is inside an obstacle")
    if g == INSCRIBED:
        raise PlanningError("goal_too_close", f"{where} is closer to an obstacle than the robot radius")
    if g == NO_INFORMATION and not params.allow_unknown:
        raise PlanningError("goal_unknown", f"{where} is in unknown space")
    return (sr, sc), (gr, gc)


def _free_start(costs: np.ndarray, cost: np.ndarray, start: tuple[int, int], radius_cells: int) -> None:
    """Let the robot leave an inscribed area it already stands in (in place).

    The robot's own cell and the inscribed (not lethal) cells within its
    radius get a high finite cost, so a slightly mislocalised robot near a
    wall still gets a plan that leads it out by the shortest way.
    """
    r, c = start
    if np.isfinite(costs[r, c]):
        return
    r0, r1 = max(r - radius_cells, 0), min(r + radius_cells + 1, costs.shape[0])
    c0, c1 = max(c - radius_cells, 0), min(c + radius_cells + 1, costs.shape[1])
    rr, cc = np.mgrid[r0:r1, c0:c1]
    disk = (rr - r) ** 2 + (cc - c) ** 2 <= radius_cells ** 2
    sub = costs[r0:r1, c0:c1]
    inscribed = disk & (cost[r0:r1, c0:c1] == INSCRIBED)
    high = float(np.nanmax(np.where(np.isfinite(costs), costs, 0.0))) * 4.0 + 1.0
    sub[inscribed] = high
    costs[r, c] = high


def _mcp_path(costs: np.ndarray, start: tuple[int, int], goal: tuple[int, int]) -> np.ndarray | None:
    """Exact 8-connected minimum-cost grid path (M, 2) or None when unreachable."""
    mcp = MCP_Geometric(costs, fully_connected=True)
    cum, _ = mcp.find_costs([start], [goal], find_all_ends=True)
    if not np.isfinite(cum[goal]):
        return None
    return np.asarray(mcp.traceback(goal), dtype=np.int64)


def _segment_ok(costs: np.ndarray, a: np.ndarray, b: np.ndarray, sub_cost: np.ndarray) -> np.ndarray:
    """For segments from cell ``a`` to each cell in ``b`` (K, 2): straight line no worse than the
    grid sub-path (``sub_cost`` (K,)) and never through an impassable cell."""
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    n = int(np.ceil(length.max() * 2)) + 2
    t = np.linspace(0.0, 1.0, n)
    rr = np.rint(a[0] + d[:, 0, None] * t[None, :]).astype(np.int64)
    cc = np.rint(a[1] + d[:, 1, None] * t[None, :]).astype(np.int64)
    c = costs.ravel()[rr * costs.shape[1] + cc]            # one flat gather
    # an impassable sample makes the sum inf, and inf <= a finite sub-path cost is False
    line_cost = c.sum(axis=1) / n * length
    return line_cost <= sub_cost + 1e-9


def smooth_path(cells: np.ndarray, costs: np.ndarray, lookahead: int = 80) -> np.ndarray:
    """String-pull a grid path: greedily replace runs of cells by straight segments that cross
    only passable cells and cost no more than the run they replace.  Returns the kept cells."""
    if len(cells) <= 2:
        return cells
    c = costs[cells[:, 0], cells[:, 1]]
    steps = np.hypot(*np.diff(cells, axis=0).T) * 0.5 * (c[:-1] + c[1:])
    cum = np.concatenate(([0.0], np.cumsum(steps)))
    keep = [0]
    i = 0
    n = len(cells)
    while i < n - 1:
        js = np.arange(i + 1, min(i + lookahead, n - 1) + 1)
        ok = _segment_ok(costs, cells[i].astype(float), cells[js].astype(float), cum[js] - cum[i])
        ok[0] = True   # the neighbour is always reachable
        j = int(js[np.nonzero(ok)[0].max()])
        keep.append(j)
        i = j
    return cells[keep]


def resample(points: np.ndarray, spacing: float) -> np.ndarray:
    """Polyline resampled at ``spacing`` m (end points kept)."""
    if len(points) < 2:
        return points.copy()
    seg = np.hypot(*np.diff(points, axis=0).T)
    s = np.concatenate(([0.0], np.cumsum(seg)))
    if s[-1] <= 0.0:
        return points[[0, -1]].copy()
    n = max(int(math.ceil(s[-1] / spacing)), 1)
    q = np.linspace(0.0, s[-1], n + 1)
    return np.column_stack((np.interp(q, s, points[:, 0]), np.interp(q, s, points[:, 1])))


class DijkstraPlanner:
    """Exact Dijkstra on the full grid (scikit-image MCP_Geometric)."""

    def __init__(self, params: PlannerParams, robot_radius: float = 0.2) -> None:
        self.params = params
        self.robot_radius = robot_radius
        self.cache = GridCache()
        self._start_freed = False    # the last _prepare gave the start area a way out (costs differ from cache)
        # the cache and _start_freed are per plan: one plan at a time per instance (move_base plans
        # under its own lock already; this keeps other callers' threads safe too)
        self._lock = threading.Lock()

    def _prepare(self, costmap: Costmap, start, goal) -> tuple[np.ndarray, tuple[int, int], tuple[int, int]]:
        s, g = _check_endpoints(costmap, start, goal, self.params)
        costs = self.cache.costs(costmap, self.params)
        self._start_freed = not np.isfinite(costs[s])
        if self._start_freed:      # rare: copy, the cached grid stays as the costmap says
            costs = costs.copy()
            _free_start(costs, costmap.cost, s, int(math.ceil(self.robot_radius / costmap.info.resolution)))
        return costs, s, g

    def _grid_path(self, costs: np.ndarray, s: tuple[int, int], g: tuple[int, int]) -> np.ndarray | None:
        return _mcp_path(costs, s, g)

    def plan(self, costmap: Costmap, start: tuple[float, float], goal: tuple[float, float]) -> Plan:
        """Cheapest path from ``start`` to ``goal`` (m) on the costmap; PlanningError if none."""
        t0 = time.perf_counter()
        with self._lock:
            costs, s, g = self._prepare(costmap, start, goal)
            cells = self._grid_path(costs, s, g)
        if cells is None:
            raise PlanningError("no_path", f"no path from ({start[0]:.4g}, {start[1]:.4g}) to goal "
                                f"({goal[0]:.4g}, {goal[1]:.4g}): it is unreachable")
        total = path_cost(cells, costs)
        kept = smooth_path(cells, costs) if self.params.smooth else cells
        x, y = costmap.info.cell_to_world(kept[:, 0], kept[:, 1])
        pts = np.column_stack((x, y))
        # exact start and goal instead of their cell centres
        pts[0] = start
        pts[-1] = goal
        pts = resample(pts, self.params.path_resolution)
        return Plan(pts, cells, total, time.perf_counter() - t0)


class HierarchicalPlanner(DijkstraPlanner):
    """Coarse-to-fine Dijkstra: coarse path on a block-averaged grid, exact search in its corridor."""

    def _grid_path(self, costs: np.ndarray, s: tuple[int, int], g: tuple[int, int]) -> np.ndarray | None:
        p = self.params
        if costs.size <= p.full_search_cells:
            return _mcp_path(costs, s, g)
        k = p.coarse_factor
        h, w = costs.shape
        # the coarse grid depends on the costmap only: cached with it (rebuilt when the start area was freed)
        coarse = coarse_grid(costs, p) if self._start_freed else self.cache.coarse(p)
        coarse = coarse.copy()
        H, W = coarse.shape
        cs, cg = (s[0] // k, s[1] // k), (g[0] // k, g[1] // k)
        coarse[cs] = min(coarse[cs], costs[s])
        coarse[cg] = min(coarse[cg], costs[g])
        cpath = _cropped_mcp_path(coarse, cs, cg, p.coarse_crop)
        if cpath is None:
            return None   # a coarse cell is blocked only if all its cells are: no fine path either
        mask = np.zeros((H, W), dtype=np.uint8)
        mask[cpath[:, 0], cpath[:, 1]] = 1
        mask = _dilate(mask, p.corridor_margin)
        # expand only the corridor's bounding box to full resolution
        rows, cols = np.nonzero(mask.any(axis=1))[0], np.nonzero(mask.any(axis=0))[0]
        r0, c0 = int(rows[0]), int(cols[0])
        box = mask[r0:rows[-1] + 1, c0:cols[-1] + 1]
        fine = np.repeat(np.repeat(box, k, axis=0), k, axis=1)[:h - r0 * k, :w - c0 * k]
        path = _corridor_path(costs, fine, s, g, origin=(r0 * k, c0 * k))
        if path is None:
            return _mcp_path(costs, s, g)
        return path


def coarse_grid(costs: np.ndarray, p: PlannerParams) -> np.ndarray:
    """Block-averaged cost grid (``coarse_factor`` x coarser, float64) for the hierarchical planner.

    Blocked cells count at a large penalty: a coarse cell with a wall in it
    stays passable (a door may be narrower than a coarse cell) but is avoided
    when an open way exists, so the corridor search rarely needs the full-grid
    fallback.  A coarse cell is ``inf`` only if all its cells are blocked.
    """
    k = p.coarse_factor
    h, w = costs.shape
    H, W = -(-h // k), -(-w // k)
    blocked = ~np.isfinite(costs)
    penalty = np.float32(PENALTY * (p.neutral_cost + p.cost_factor))
    pen = np.full((H * k, W * k), penalty, dtype=np.float32)
    pen[:h, :w] = costs            # in place: np.where would allocate a float64 copy of the map
    pen[:h, :w][blocked] = penalty
    coarse = cv2.resize(pen, (W, H), interpolation=cv2.INTER_AREA).astype(np.float64)
    full = np.ones((H * k, W * k), dtype=bool)       # 1 byte/cell (a float32 area resize took 4)
    full[:h, :w] = blocked
    coarse[full.reshape(H, k, W, k).all(axis=(1, 3))] = np.inf
    return coarse


class GridCache:
    """Cost grids derived from one costmap, kept while the costmap's content is unchanged.

    move_base replans at ``planner_frequency`` on a costmap that rarely changes
    between plans; the per-cell traversal costs and the coarse grid are then
    reused.  The key is the costmap's content (an exact byte comparison with a
    kept copy, ~0.1 ms per M cells), its geometry and the planner params, so
    an update in place, a new map or new params all invalidate it.  Cached
    arrays are read-only.
    """

    def __init__(self) -> None:
        self._cost: np.ndarray | None = None
        self._key: tuple | None = None
        self._costs: np.ndarray | None = None
        self._coarse: np.ndarray | None = None
        self.builds = 0     # how often the cost grid was (re)built (tests, diagnostics)

    def costs(self, costmap: Costmap, params: PlannerParams) -> np.ndarray:
        """Read-only traversal costs of ``costmap`` (see :func:`cell_costs`), rebuilt if it changed."""
        key = (costmap.info, params)
        cost = costmap.cost
        if not (self._key == key and self._cost is not None and self._cost.shape == cost.shape
                and np.array_equal(self._cost, cost)):
            self._cost = cost.copy()
            self._key = key
            self._costs = cell_costs(cost, params)
            self._costs.setflags(write=False)
            self._coarse = None
            self.builds += 1
        return self._costs

    def coarse(self, params: PlannerParams) -> np.ndarray:
        """Read-only coarse grid of the costs last returned by :meth:`costs`."""
        if self._costs is None:
            raise RuntimeError("GridCache.coarse before GridCache.costs")
        if self._coarse is None:
            self._coarse = coarse_grid(self._costs, params)
            self._coarse.setflags(write=False)
        return self._coarse


def _cropped_mcp_path(coarse: np.ndarray, cs: tuple[int, int], cg: tuple[int, int],
                      crop: float) -> np.ndarray | None:
    """Coarse path searched first in the bounding box of start and goal grown by ``crop`` x their
    distance (at least ``MIN_CROP`` coarse cells), on the whole coarse grid if the box has no path.

    Like the corridor, a heuristic stage: a detour leaving the box is not
    considered (the exact search happens later, at full resolution in the
    corridor); on the bench's office routes the box's coarse path cost equals
    the whole grid's.  ``crop`` <= 0 searches the whole grid.
    """
    H, W = coarse.shape
    if crop > 0:
        m = int(max(MIN_CROP, crop * math.hypot(cs[0] - cg[0], cs[1] - cg[1])))
        r0, r1 = max(min(cs[0], cg[0]) - m, 0), min(max(cs[0], cg[0]) + m + 1, H)
        c0, c1 = max(min(cs[1], cg[1]) - m, 0), min(max(cs[1], cg[1]) + m + 1, W)
        if (r1 - r0) * (c1 - c0) < H * W:
            path = _mcp_path(coarse[r0:r1, c0:c1], (cs[0] - r0, cs[1] - c0), (cg[0] - r0, cg[1] - c0))
            if path is not None:
                return path + np.array([r0, c0])
    return _mcp_path(coarse, cs, cg)


def _corridor_path(costs: np.ndarray, corridor: np.ndarray, s: tuple[int, int],
                   g: tuple[int, int], origin: tuple[int, int] = (0, 0)) -> np.ndarray | None:
    """Exact Dijkstra restricted to the corridor cells (scipy csgraph on just those cells).

    ``corridor`` is a mask of a window of ``costs`` whose first cell is ``origin`` (row, col).
    The work grows with the corridor's area, not with its bounding box, which
    matters for long diagonal routes across a large map.
    """
    rows = np.nonzero(corridor.any(axis=1))[0]
    cols = np.nonzero(corridor.any(axis=0))[0]
    wr0, wc0 = rows[0], cols[0]
    r0, r1, c0, c1 = wr0 + origin[0], rows[-1] + 1 + origin[0], wc0 + origin[1], cols[-1] + 1 + origin[1]
    sub = costs[r0:r1, c0:c1]
    ok = corridor[wr0:wr0 + sub.shape[0], wc0:wc0 + sub.shape[1]].astype(bool) & np.isfinite(sub)
    hb, wb = ok.shape
    ids = np.flatnonzero(ok)
    n = ids.size
    # int32 node ids (csgraph's own index type): the table spans the corridor's bounding box, which is
    # the whole map for a diagonal route
    node = np.full(hb * wb, -1, dtype=np.int32)
    node[ids] = np.arange(n, dtype=np.int32)
    node = node.reshape(hb, wb)
    sr, sc, gr, gc = s[0] - r0, s[1] - c0, g[0] - r0, g[1] - c0
    if not (0 <= sr < hb and 0 <= sc < wb and 0 <= gr < hb and 0 <= gc < wb) or node[sr, sc] < 0 \
            or node[gr, gc] < 0:
        return None
    # node table with a border of -1, so every neighbour lookup is in range; edges are built row by
    # row in node order, which is CSR order already (no COO sort)
    table = np.full((hb + 2, wb + 2), -1, dtype=np.int32)
    table[1:-1, 1:-1] = node
    rr, cc = np.divmod(ids, wb)
    flat = (rr + 1) * (wb + 2) + (cc + 1)                              # ids in the padded table
    nb = table.ravel()[flat[:, None] + (_DR * (wb + 2) + _DC)]        # (n, 8) neighbour ids or -1
    keep = nb >= 0
    c = sub.ravel()[ids]
    wt = _STEP * (0.5 * (c[:, None] + c[np.where(keep, nb, 0)]))
    indptr = np.zeros(n + 1, dtype=np.int32)
    np.cumsum(keep.sum(axis=1), out=indptr[1:])
    graph = csr_matrix((wt[keep], nb[keep], indptr), shape=(n, n))
    start, goal = int(node[sr, sc]), int(node[gr, gc])
    dist, pred = dijkstra(graph, directed=True, indices=start, return_predecessors=True)
    if not np.isfinite(dist[goal]):
        return None
    chain = [goal]
    while chain[-1] != start:
        chain.append(int(pred[chain[-1]]))
    cells = np.column_stack(np.divmod(ids[np.array(chain[::-1])], wb))
    return cells + np.array([r0, c0])


PENALTY = 100.0   # x the costliest passable cell: weight of a blocked cell in a coarse block
MIN_CROP = 24     # coarse cells: least margin of the coarse search box (6 m at 5 cm x 5: an office room)
_OFFSETS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]
_DR = np.array([d[0] for d in _OFFSETS])
_DC = np.array([d[1] for d in _OFFSETS])
_STEP = np.hypot(_DR, _DC)


def _dilate(mask: np.ndarray, m: int) -> np.ndarray:
    """Binary dilation with a (2m+1)^2 square."""
    kernel = np.ones((2 * m + 1, 2 * m + 1), dtype=np.uint8)
    return cv2.dilate(mask.astype(np.uint8), kernel)


PLANNERS = {"dijkstra": DijkstraPlanner, "hierarchical": HierarchicalPlanner}


def make_planner(name: str, params: PlannerParams, robot_radius: float = 0.2) -> GlobalPlanner:
    """Planner implementation by name (``dijkstra`` or ``hierarchical``)."""
    try:
        cls = PLANNERS[name]
    except KeyError:
        raise ValueError(f"unknown planner {name!r}; choose one of {', '.join(sorted(PLANNERS))}") from None
    return cls(params, robot_radius)
