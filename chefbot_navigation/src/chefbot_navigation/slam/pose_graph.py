"""2-D pose graph optimised with ``scipy.optimize.least_squares`` (sparse Jacobian).

Nodes are robot poses (x, y, yaw); an edge (i, j, z) says "pose j seen from
pose i is z" with a diagonal information given as standard deviations.  The
first node is held fixed (it defines the map frame).  The Jacobian is written
analytically as a ``scipy.sparse`` matrix, so the trust-region solver (``trf``
with LSMR) scales to thousands of nodes; a Huber loss (beyond 5 sigma) keeps a wrong loop
closure from bending the whole map.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.optimize import least_squares

from chefbot_common.geometry import Pose2D


@dataclass
class Edge:
    """Constraint: pose ``j`` in the frame of pose ``i`` is ``z``; sigmas (m, m, rad)."""

    i: int
    j: int
    z: Pose2D
    sigma: tuple[float, float, float]
    loop: bool = False
    tag: str = ""            # who added it ("refine": the final refinement pass, replaced per pass)


class PoseGraph:
    """Nodes (poses) and edges; :meth:`optimize` moves nodes 1..n-1."""

    def __init__(self) -> None:
        self.poses: list[Pose2D] = []
        self.edges: list[Edge] = []

    def add_node(self, pose: Pose2D) -> int:
        """Append a node; returns its index."""
        self.poses.append(pose)
        return len(self.poses) - 1

    def add_edge(self, i: int, j: int, z: Pose2D, sigma: tuple[float, float, float], loop: bool = False,
                 tag: str = "") -> None:
        """Add a relative-pose constraint between existing nodes i and j (``tag``: see :meth:`remove_edges`)."""
        n = len(self.poses)
        if not (0 <= i < n and 0 <= j < n) or i == j:
            raise ValueError(f"edge ({i}, {j}) does not join two different nodes of {n}")
        if min(sigma) <= 0:
            raise ValueError(f"edge sigmas must be > 0, got {sigma}")
        self.edges.append(Edge(i, j, z, sigma, loop, tag))

    def remove_edges(self, tag: str) -> int:
        """Drop every edge added with ``tag``; returns how many."""
        n = len(self.edges)
        self.edges = [e for e in self.edges if e.tag != tag]
        return n - len(self.edges)

    def _arrays(self):
        e = self.edges
        ii = np.array([x.i for x in e], dtype=np.int64)
        jj = np.array([x.j for x in e], dtype=np.int64)
        z = np.array([[x.z.x, x.z.y, x.z.yaw] for x in e], dtype=float)
        w = 1.0 / np.array([x.sigma for x in e], dtype=float)
        return ii, jj, z, w

    def optimize(self, max_nfev: int = 50) -> float:
        """Least-squares adjustment of all nodes but the first; returns the final cost."""
        n = len(self.poses)
        if n < 2 or not self.edges:
            return 0.0
        ii, jj, z, w = self._arrays()
        m = len(ii)
        x0 = np.array([[p.x, p.y, p.yaw] for p in self.poses], dtype=float)
        anchor = x0[0].copy()

        def full(v: np.ndarray) -> np.ndarray:
            return np.vstack((anchor, v.reshape(n - 1, 3)))

        def residual(v: np.ndarray) -> np.ndarray:
            x = full(v)
            d = x[jj, :2] - x[ii, :2]
            c, s = np.cos(x[ii, 2]), np.sin(x[ii, 2])
            r = np.empty((m, 3))
            r[:, 0] = c * d[:, 0] + s * d[:, 1] - z[:, 0]
            r[:, 1] = -s * d[:, 0] + c * d[:, 1] - z[:, 1]
            r[:, 2] = np.angle(np.exp(1j * (x[jj, 2] - x[ii, 2] - z[:, 2])))
            return (r * w).ravel()

        def jacobian(v: np.ndarray) -> sparse.csr_matrix:
            x = full(v)
            d = x[jj, :2] - x[ii, :2]
            c, s = np.cos(x[ii, 2]), np.sin(x[ii, 2])
            rows, cols, vals = [], [], []

            def put(k_res: int, node: np.ndarray, k_var: int, val: np.ndarray) -> None:
                keep = node > 0          # node 0 is fixed: no column
                rows.append((np.arange(m) * 3 + k_res)[keep])
                cols.append(((node - 1) * 3 + k_var)[keep])
                vals.append((val * w[:, k_res])[keep])

            # r0 = c dx + s dy ; r1 = -s dx + c dy ; r2 = th_j - th_i
            put(0, ii, 0, -c), put(0, ii, 1, -s), put(0, ii, 2, -s * d[:, 0] + c * d[:, 1])
            put(0, jj, 0, c), put(0, jj, 1, s)
            put(1, ii, 0, s), put(1, ii, 1, -c), put(1, ii, 2, -c * d[:, 0] - s * d[:, 1])
            put(1, jj, 0, -s), put(1, jj, 1, c)
            put(2, ii, 2, -np.ones(m)), put(2, jj, 2, np.ones(m))
            return sparse.csr_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                                     shape=(3 * m, 3 * (n - 1)))

        sol = least_squares(residual, x0[1:].ravel(), jac=jacobian, method="trf", tr_solver="lsmr",
                            loss="huber", f_scale=5.0, max_nfev=max_nfev, x_scale="jac")
        x = full(sol.x)
        self.poses = [Pose2D(float(a), float(b), float(np.angle(np.exp(1j * c)))) for a, b, c in x]
        return float(sol.cost)
