"""Exact grid Dijkstra with scipy.sparse.csgraph: the reference for tests and benchmarks.

Same graph as the planners: 8-connected cells, edge cost = step length (1 or
sqrt 2 cells) x mean of the two cells' traversal costs, impassable (inf)
cells without edges.  Slow on purpose-free generality: builds the whole
sparse graph every call.
"""
from __future__ import annotations

import numpy as np
from scipy.sparse import csr_matrix
from scipy.sparse.csgraph import dijkstra

OFFSETS = [(-1, -1), (-1, 0), (-1, 1), (0, -1), (0, 1), (1, -1), (1, 0), (1, 1)]


def grid_graph(costs: np.ndarray) -> csr_matrix:
    """Sparse adjacency of the 8-connected grid of passable cells."""
    h, w = costs.shape
    idx = np.arange(h * w).reshape(h, w)
    ok = np.isfinite(costs)
    src, dst, wt = [], [], []
    for dr, dc in OFFSETS:
        r0, r1 = max(0, -dr), h - max(0, dr)
        c0, c1 = max(0, -dc), w - max(0, dc)
        a = (slice(r0, r1), slice(c0, c1))
        b = (slice(r0 + dr, r1 + dr), slice(c0 + dc, c1 + dc))
        both = ok[a] & ok[b]
        src.append(idx[a][both])
        dst.append(idx[b][both])
        wt.append(np.hypot(dr, dc) * 0.5 * (costs[a][both] + costs[b][both]))
    return csr_matrix((np.concatenate(wt), (np.concatenate(src), np.concatenate(dst))), shape=(h * w, h * w))


def exact_cost(costs: np.ndarray, start: tuple[int, int], goal: tuple[int, int],
               graph: csr_matrix | None = None) -> float:
    """Minimum path cost from start to goal cell (inf if unreachable)."""
    g = grid_graph(costs) if graph is None else graph
    w = costs.shape[1]
    d = dijkstra(g, directed=True, indices=start[0] * w + start[1], min_only=True)
    return float(d[goal[0] * w + goal[1]])
