"""2-D pose graph optimised by Levenberg-Marquardt on its sparse normal equations.

Nodes are robot poses (x, y, yaw); an edge (i, j, z) says "pose j seen from
pose i is z" with a diagonal information given as standard deviations.  The
first node is held fixed (it defines the map frame).  The Jacobian is written
analytically as a ``scipy.sparse`` matrix; each step solves the damped normal
equations with ``scipy.sparse.linalg.spsolve`` (SuperLU).  A pose graph's normal
matrix is a near-banded chain plus a few loop entries, so a direct solve is
exact and cheap; a Huber loss (beyond ``HUBER`` sigma, by iteratively
reweighting) limits the pull of one bad residual - but not enough: one false
loop edge 1.5 m / 20 deg off still bends a square of 80 keyframes by 0.7-0.8 m
(test_slam_robust.py).  With ``robust_loops`` (the default), loop edges the Huber optimum
cannot fit (chi^2 > ``phi``) start a second pass with dynamic covariance scaling
(Agarwal et al., ICRA 2013: a closed form of switchable constraints): each loop
edge's information is scaled by s^2, s = min(1, 2 phi / (phi + chi^2)); the
false edge ends at a weight of ~3e-4 and the map moves 1-2 mm.  Odometry edges
keep the Huber loss.  The second pass starts from the Huber optimum, where true
closures fit (from the drifted input poses a true closure of a long drift
misfits like a false one and would be scaled down too).

Written here rather than calling ``scipy.optimize.least_squares`` (trf with
LSMR, the Huber loss, ``x_scale="jac"``: what this module used until 2026-11-24):
on the graphs of a live hotel run (985-1426 nodes) that took 0.60-1.42 s per
optimisation, this 0.045-0.065 s, to the same cost (equal to 4 digits, or
lower: trf stopped before converging) and poses within 0.8 cm / 0.07 deg.  The
live slam node takes no scan while a loop closure is optimised.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import sparse
from scipy.sparse.linalg import spsolve

from chefbot_common.geometry import Pose2D

HUBER = 5.0           # residuals (in sigmas) beyond which the loss grows linearly
# chi^2 of a loop edge (3 residuals in sigmas) beyond which the robust pass scales it down (PoseGraph.optimize):
# ~ the 97 % point of chi^2 with 3 dof.  On the square of test_slam_robust.py phi 3-20 all reject the false
# edge and keep the true ones at weight 1; phi 1 (Agarwal's default, for calibrated sigmas: ours are guesses)
# scaled a true closure to 0.21, phi 50 missed the false edge
DCS_PHI = 9.0


def huber_cost(r: np.ndarray, k: float = HUBER) -> float:
    """0.5 * sum of the Huber loss of the residuals ``r`` (in sigmas): r^2 within ``k``, 2 k |r| - k^2 beyond
    (``scipy.optimize.least_squares``' ``loss="huber", f_scale=k`` cost)."""
    a = np.abs(r)
    return float(0.5 * np.sum(np.where(a <= k, a * a, 2.0 * k * a - k * k)))


@dataclass
class Edge:
    """Constraint: pose ``j`` in the frame of pose ``i`` is ``z``; sigmas (m, m, rad)."""

    i: int
    j: int
    z: Pose2D
    sigma: tuple[float, float, float]
    loop: bool = False
    tag: str = ""            # who added it ("refine": the final refinement pass, replaced per pass)
    weight: float = 1.0      # least factor the last optimize put on its information (< 1: Huber or DCS)


class PoseGraph:
    """Nodes (poses) and edges; :meth:`optimize` moves nodes 1..n-1."""

    def __init__(self, robust_loops: bool = True, phi: float = DCS_PHI) -> None:
        if not phi > 0:
            raise ValueError(f"phi must be > 0, got {phi}")
        self.poses: list[Pose2D] = []
        self.edges: list[Edge] = []
        self.robust_loops = robust_loops      # a second, DCS pass for loop edges that stay misfit (optimize)
        self.phi = phi                        # DCS threshold (chi^2) of that pass

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

    def optimize(self, max_iterations: int = 50) -> float:
        """Least-squares adjustment of all nodes but the first (Levenberg-Marquardt, at most
        ``max_iterations`` steps; it stops once a step lowers the cost by less than a relative 1e-9 or
        moves no coordinate by more than 1e-7); returns the final cost (see :func:`huber_cost`; after a
        robust pass, :func:`robust_cost`).  With ``robust_loops``, a loop edge that still misfits by more
        than ``phi`` (chi^2) at that optimum starts a second pass in which loop edges are scaled down
        by dynamic covariance scaling (see :func:`dcs_weight`); the final per-edge weights are in
        ``Edge.weight``."""
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

        def huber_weights(r: np.ndarray) -> np.ndarray:
            a = np.abs(r)
            return np.where(a <= HUBER, 1.0, HUBER / np.maximum(a, 1e-12))

        loop = np.array([e.loop for e in self.edges], dtype=bool)
        loop_rows = np.repeat(loop, 3)

        def robust_weights(r: np.ndarray) -> np.ndarray:
            out = huber_weights(r)
            out[loop_rows] = np.repeat(dcs_weight(_chi2(r)[loop], self.phi), 3)
            return out

        x = x0[1:].ravel()
        x, r, cost = _levenberg_marquardt(x, residual, jacobian, huber_cost, huber_weights, max_iterations)
        weight = huber_weights(r)
        if self.robust_loops and loop.any() and _chi2(r)[loop].max() > self.phi:
            # a loop edge the optimum cannot fit (a false closure, or a true one fighting a false one):
            # go on from here with the loop edges scaled down by their misfit.  Started from the Huber
            # optimum, not from the input poses: there a true closure of a long drift misfits as much as
            # a false one and would be scaled down too
            x, r, cost = _levenberg_marquardt(x, residual, jacobian, lambda res: robust_cost(res, loop, self.phi),
                                              robust_weights, max_iterations)
            weight = robust_weights(r)
        for e, wt in zip(self.edges, weight.reshape(m, 3).min(axis=1), strict=True):
            e.weight = float(wt)
        self.poses = [Pose2D(float(px), float(py), float(np.angle(np.exp(1j * pyaw)))) for px, py, pyaw in full(x)]
        return cost

    def outliers(self, below: float = 0.1) -> list[Edge]:
        """Loop edges whose information the last :meth:`optimize` scaled below ``below`` (down-weighted
        closures, most likely false: for the front end's log)."""
        return [e for e in self.edges if e.loop and e.weight < below]


def _chi2(r: np.ndarray) -> np.ndarray:
    """Per-edge squared Mahalanobis misfit of the stacked residuals (in sigmas, 3 per edge)."""
    return (r.reshape(-1, 3) ** 2).sum(axis=1)


def dcs_weight(chi2: np.ndarray, phi: float = DCS_PHI) -> np.ndarray:
    """Factor on a loop edge's information by dynamic covariance scaling (Agarwal et al., ICRA 2013):
    s^2 with s = min(1, 2 phi / (phi + chi2)), ``chi2`` the edge's squared misfit in sigmas."""
    s = np.minimum(1.0, 2.0 * phi / (phi + np.asarray(chi2, dtype=float)))
    return s * s


def robust_cost(r: np.ndarray, loop: np.ndarray, phi: float = DCS_PHI) -> float:
    """The robust pass's cost: :func:`huber_cost` of the non-loop residuals plus 0.5 * rho(chi2) per loop edge
    (``loop``: a mask of edges), rho = chi2 up to ``phi``, then phi (3 chi2 - phi) / (phi + chi2) (bounded by
    3 phi: the kernel whose reweighting is :func:`dcs_weight`)."""
    chi2 = _chi2(r)[loop]
    rho = np.where(chi2 <= phi, chi2, phi * (3.0 * chi2 - phi) / (phi + chi2))
    return huber_cost(r.reshape(-1, 3)[~loop]) + float(0.5 * rho.sum())


def _levenberg_marquardt(x: np.ndarray, residual, jacobian, cost_of, weights_of, max_iterations: int):
    """Minimise ``cost_of(residual(x))`` by LM on the reweighted normal equations (``weights_of(r)`` per
    residual: iteratively reweighted least squares); returns (x, residual, cost)."""
    r = residual(x)
    cost, lam = cost_of(r), 1e-4
    for _ in range(max_iterations):
        jac = jacobian(x)
        weight = weights_of(r)
        normal = (jac.T @ sparse.diags(weight) @ jac).tocsc()
        grad = jac.T @ (weight * r)
        diag = np.maximum(normal.diagonal(), 1e-9)
        improved = False
        while lam <= 1e8:
            step = spsolve(normal + sparse.diags(lam * diag, format="csc"), -grad)
            if np.all(np.isfinite(step)):
                r_new = residual(x + step)
                c_new = cost_of(r_new)
                if c_new <= cost:
                    improved = True
                    break
            lam *= 10.0
        if not improved:
            break
        gain = cost - c_new
        x, r, cost, lam = x + step, r_new, c_new, max(lam / 10.0, 1e-9)
        if gain <= 1e-9 * max(cost, 1e-12) or np.abs(step).max() < 1e-7:
            break
    return x, r, cost
