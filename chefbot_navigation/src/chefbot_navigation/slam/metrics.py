"""Map and trajectory quality against ground truth (tests and the benchmark only; pure numpy/scipy).

* :func:`map_quality`: the estimated map is resampled onto the ground-truth
  grid (same resolution; integer-cell shifts of up to ``search`` cells tried,
  the best kept — "after aligning frames").  The ground-truth cells that can be
  seen are the occupied cells bordering the reachable free space; *matched* =
  share of those with an estimated occupied cell within one cell (8-neighbour);
  *false occupied* = share of estimated occupied cells with no ground-truth
  occupied cell within one cell; *coverage* = share of the reachable free area
  that the estimate knows as free.
* :func:`ate_rms`: absolute trajectory error (RMS of position differences
  after the best rigid 2-D alignment, Horn/Umeyama without scale), the metric
  of Kümmerle et al. 2009 / Sturm et al. 2012; :func:`aligned_errors` gives
  the per-pose errors after that alignment (their max: the benchmark's ATE max).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import ndimage

from chefbot_common.grid import FREE, OccupancyMap


@dataclass
class MapQuality:
    """Fractions 0..1 and the cell shift (rows, cols) used to align the maps."""

    matched: float
    false_occupied: float
    coverage: float
    shift: tuple[int, int]


def resample(est: OccupancyMap, truth: OccupancyMap, dr: int = 0, dc: int = 0) -> np.ndarray:
    """The estimate's values on the ground-truth grid (nearest cell centre; -1 outside), shifted by cells."""
    ti = truth.info
    rows, cols = np.mgrid[0:ti.height, 0:ti.width]
    x, y = ti.cell_to_world(rows - dr, cols - dc)
    r, c = est.info.world_to_cell(x, y)
    ok = est.info.inside(r, c)
    out = np.full((ti.height, ti.width), -1, dtype=np.int8)
    out[ok] = est.data[r[ok], c[ok]]
    return out


def _within_one_cell(mask: np.ndarray) -> np.ndarray:
    """Cells at most one cell (8-neighbourhood) from a True cell of ``mask``."""
    return ndimage.binary_dilation(mask, structure=np.ones((3, 3)))


def _false_occupied(est_values: np.ndarray, gt_near: np.ndarray) -> np.ndarray:
    """Occupied in the estimate (on the truth's grid) with no ground-truth obstacle within one cell."""
    return (est_values > 50) & ~gt_near


def false_occupied_clusters(est: OccupancyMap, truth: OccupancyMap, shift: tuple[int, int] = (0, 0),
                            top: int = 3) -> list[tuple[int, float, float]]:
    """Where the false-occupied cells of ``map_quality`` are: the ``top`` largest 8-connected clusters
    as (cells, x, y of their centre in the truth's frame, m), largest first; ``shift`` is
    ``MapQuality.shift``.  For a failure report: a slipped wall is one long cluster, speckle many."""
    false = _false_occupied(resample(est, truth, *shift), _within_one_cell(truth.data > 50))
    labels, n = ndimage.label(false, structure=np.ones((3, 3)))
    if n == 0:
        return []
    sizes = ndimage.sum(false, labels, index=range(1, n + 1))
    out = []
    for k in np.argsort(sizes)[::-1][:top]:
        r, c = ndimage.center_of_mass(false, labels, k + 1)
        x, y = truth.info.cell_to_world(np.array([r]), np.array([c]))
        out.append((int(sizes[k]), float(x[0]), float(y[0])))
    return out


def reachable_free(truth: OccupancyMap, start_xy: tuple[float, float], robot_radius: float) -> np.ndarray:
    """Ground-truth free cells the robot can reach or touch with its body from ``start_xy``."""
    res = truth.info.resolution
    occ = truth.data > 50
    clear = ndimage.distance_transform_edt(~occ) * res >= robot_radius
    labels, _ = ndimage.label(clear)
    r, c = truth.info.world_to_cell(*start_xy)
    lab = labels[int(r), int(c)]
    if lab == 0:
        raise ValueError(f"start {start_xy} is not a free robot position in the ground truth")
    centres = labels == lab
    body = ndimage.distance_transform_edt(~centres) * res <= robot_radius
    return body & (truth.data == FREE)


def map_quality(est: OccupancyMap, truth: OccupancyMap, start_xy: tuple[float, float] = (0.0, 0.0),
                robot_radius: float = 0.2, search: int = 2) -> MapQuality:
    """See the module docstring; ``truth`` is the rasterised world on the same resolution."""
    if abs(est.info.resolution - truth.info.resolution) > 1e-9:
        raise ValueError(f"resolutions differ: {est.info.resolution} vs {truth.info.resolution}")
    gt_occ = truth.data > 50
    reach = reachable_free(truth, start_xy, robot_radius)
    visible = gt_occ & _within_one_cell(reach)
    gt_near = _within_one_cell(gt_occ)
    best = None
    for dr in range(-search, search + 1):
        for dc in range(-search, search + 1):
            e = resample(est, truth, dr, dc)
            e_occ = e > 50
            e_near = _within_one_cell(e_occ)
            matched = float(e_near[visible].mean()) if visible.any() else 0.0
            false = float(_false_occupied(e, gt_near).sum() / max(e_occ.sum(), 1))
            cov = float((e[reach] == FREE).mean()) if reach.any() else 0.0
            q = MapQuality(matched, false, cov, (dr, dc))
            if best is None or q.matched - q.false_occupied > best.matched - best.false_occupied:
                best = q
    return best


def aligned_errors(est: np.ndarray, truth: np.ndarray) -> np.ndarray:
    """(N,) position error (m) of each pose after the best rigid alignment of est onto truth ((N, 2) each,
    at the same stamps)."""
    est, truth = np.asarray(est, float), np.asarray(truth, float)
    if est.shape != truth.shape or len(est) < 2:
        raise ValueError(f"need two matching (N >= 2, 2) trajectories, got {est.shape} and {truth.shape}")
    me, mt = est.mean(axis=0), truth.mean(axis=0)
    h = (est - me).T @ (truth - mt)
    u, _, vt = np.linalg.svd(h)
    d = np.sign(np.linalg.det(vt.T @ u.T))
    rot = vt.T @ np.diag([1.0, d]) @ u.T
    aligned = (rot @ (est - me).T).T + mt
    return np.sqrt(((aligned - truth) ** 2).sum(axis=1))


def ate_rms(est: np.ndarray, truth: np.ndarray) -> float:
    """RMS (m) of position error after the best rigid alignment; est, truth (N, 2) at the same stamps."""
    return float(np.sqrt(np.mean(aligned_errors(est, truth) ** 2)))
