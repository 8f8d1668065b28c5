"""Resampling, the KLD bound on the particle count, and pose clusters (vectorised).

* Low-variance (systematic) resampling: one random offset, N evenly spaced
  pointers into the cumulative weights (Probabilistic Robotics, table 4.4).
* KLD sampling (Fox 2003, as in ROS's amcl ``pf_resample_limit``): with ``k``
  occupied histogram bins the number of samples that keeps the K-L divergence
  between the sample-based and the true posterior below ``kld_err`` with
  probability given by ``kld_z`` is

      n = (k - 1) / (2 err) · (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) · z)³

  ``kld_z`` is used directly as the normal quantile z, exactly as amcl does
  with its parameter of that name (0.99 there means z = 0.99).
  amcl draws particles one by one and stops once the count passes the bound of
  the bins seen so far; here all ``max_particles`` are drawn at once, in random
  order, and the first count that passes the bound is found with a cumulative
  sum over "first particle in a new bin" — the same rule without a Python loop.
* Clusters: particles are binned (0.5 m, 0.5 m, 10°, amcl's kd-tree leaf
  size); occupied bins that touch (26-neighbourhood, yaw wrapping around) form
  a cluster (``scipy.ndimage.label``).  The estimate is the heaviest cluster's
  weighted mean, as amcl picks its heaviest hypothesis.
"""
from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

BIN_XY = 0.5                     # m, amcl's pf_kdtree cell size
BIN_YAW = math.radians(10.0)     # rad
N_YAW_BINS = int(round(2.0 * math.pi / BIN_YAW))


def low_variance_indices(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """``n`` indices drawn by systematic resampling of normalised or unnormalised ``weights``."""
    c = np.cumsum(weights, dtype=np.float64)
    if not (c[-1] > 0 and math.isfinite(c[-1])):
        raise ValueError(f"weights must have a positive finite sum, got {c[-1]}")
    pointers = (rng.random() + np.arange(n)) * (c[-1] / n)
    return np.minimum(np.searchsorted(c, pointers, side="right"), len(weights) - 1)


def kld_bound(k: np.ndarray | int, err: float, z: float) -> np.ndarray:
    """Samples needed for ``k`` occupied bins (amcl's pf_resample_limit before clamping).

    k <= 1 gives 0 (so ``min_particles``): one bin is a converged set.  amcl
    returns ``max_particles`` there instead, which makes a well-localized
    filter whose particles all share one 0.5 m bin run at the maximum count.
    """
    k = np.asarray(k, dtype=np.float64)
    with np.errstate(divide="ignore", invalid="ignore"):
        b = 2.0 / (9.0 * (k - 1.0))
        n = (k - 1.0) / (2.0 * err) * (1.0 - b + np.sqrt(b) * z) ** 3
    return np.where(k > 1.0, np.ceil(n), 0.0)


def pose_bins(particles: np.ndarray) -> np.ndarray:
    """(N, 3) integer bin indices of particles (x, y, yaw in 0..N_YAW_BINS-1)."""
    bx = np.floor(particles[:, 0] / BIN_XY).astype(np.int64)
    by = np.floor(particles[:, 1] / BIN_XY).astype(np.int64)
    byaw = np.floor((particles[:, 2] + math.pi) / BIN_YAW).astype(np.int64) % N_YAW_BINS
    return np.stack([bx, by, byaw], axis=1)


def bin_keys(bins: np.ndarray) -> np.ndarray:
    """One int64 key per bin triple (for np.unique)."""
    bx, by, byaw = bins[:, 0] + (1 << 20), bins[:, 1] + (1 << 20), bins[:, 2]
    return (bx << 30) | (by << 8) | byaw


def kld_count(particles_in_draw_order: np.ndarray, err: float, z: float, n_min: int, n_max: int) -> int:
    """How many of these particles (drawn in random order) amcl's KLD rule keeps, in [n_min, n_max]."""
    n = min(len(particles_in_draw_order), n_max)
    keys = bin_keys(pose_bins(particles_in_draw_order[:n]))
    _, first = np.unique(keys, return_index=True)
    new_bin = np.zeros(n, dtype=np.int64)
    new_bin[first] = 1
    k = np.cumsum(new_bin)                      # bins seen after 1..n samples
    count = np.arange(1, n + 1)
    ok = np.flatnonzero((count >= kld_bound(k, err, z)) & (count >= n_min))
    return int(count[ok[0]]) if len(ok) else n


@dataclass(frozen=True)
class Cluster:
    """A pose hypothesis: weighted mean (x m, y m, yaw rad), total weight (0..1), member count,
    covariance (3, 3) of its members."""

    mean: tuple[float, float, float]
    weight: float
    count: int
    cov: np.ndarray | None = field(default=None, compare=False)   # an array: not part of equality


def weighted_mean_cov(particles: np.ndarray, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Weighted mean (3,) and covariance (3, 3) of poses; yaw by circular statistics.

    The yaw variance is amcl's ``-2 ln R`` (R = length of the mean unit vector),
    its cross terms with x, y use the yaw offsets from the circular mean.
    """
    w = w / w.sum()
    cs, sn = float(w @ np.cos(particles[:, 2])), float(w @ np.sin(particles[:, 2]))
    yaw = math.atan2(sn, cs)
    mean = np.array([float(w @ particles[:, 0]), float(w @ particles[:, 1]), yaw])
    d = particles - mean
    d[:, 2] = np.mod(d[:, 2] + math.pi, 2.0 * math.pi) - math.pi
    cov = (d * w[:, None]).T @ d
    r = min(math.hypot(cs, sn), 1.0)
    cov[2, 2] = -2.0 * math.log(r) if r > 1e-12 else math.pi ** 2
    return mean, cov


def clusters(particles: np.ndarray, weights: np.ndarray, limit: int = 8) -> list[Cluster]:
    """The ``limit`` heaviest pose clusters, heaviest first."""
    w = weights / weights.sum()
    bins = pose_bins(particles)
    lo = bins[:, :2].min(axis=0) - 1            # one empty bin of margin: np.roll below never wraps onto data
    shape = (*(bins[:, :2].max(axis=0) - lo + 2), N_YAW_BINS)
    grid = np.zeros(shape, dtype=bool)
    ix, iy, iyaw = bins[:, 0] - lo[0], bins[:, 1] - lo[1], bins[:, 2]
    grid[ix, iy, iyaw] = True
    labels, n_labels = ndimage.label(grid, structure=np.ones((3, 3, 3), dtype=bool))
    # yaw wraps: bins at yaw index 0 and N-1 (and their x/y neighbours) are adjacent too
    a = labels[:, :, 0]
    b = labels[:, :, -1]
    pairs = []
    for sx in (-1, 0, 1):
        for sy in (-1, 0, 1):
            bb = np.roll(np.roll(b, sx, axis=0), sy, axis=1)
            m = (a > 0) & (bb > 0)
            pairs.append(np.stack([a[m], bb[m]], axis=1))
    pairs = np.concatenate(pairs)
    graph = coo_matrix((np.ones(len(pairs)), (pairs[:, 0], pairs[:, 1])), shape=(n_labels + 1, n_labels + 1))
    _, comp = connected_components(graph, directed=False)
    member = comp[labels[ix, iy, iyaw]]
    ids, inv = np.unique(member, return_inverse=True)
    totals = np.bincount(inv, weights=w, minlength=len(ids))
    out = []
    for j in np.argsort(-totals)[:limit]:
        sel = inv == j
        mean, cov = weighted_mean_cov(particles[sel], w[sel])
        out.append(Cluster((float(mean[0]), float(mean[1]), float(mean[2])), float(totals[j]), int(sel.sum()), cov))
    return out
