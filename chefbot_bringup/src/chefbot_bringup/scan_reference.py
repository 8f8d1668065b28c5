"""The true motion of a standing robot from two of its own laser scans (odometry calibration, issue 31).

Pure numpy/scipy, no rospy.  The guided odometry calibration drives the robot by its wheel
odometry (a straight line, N in-place turns, UMBmark squares) and needs the motion it really made.
The robot stands still, takes a scan, drives, stands still again and takes another; this module
returns the pose of the robot at the second scan in the frame of the robot at the first
(x forward, y left, yaw counter-clockwise; m, rad), with its quality, or refuses with
:class:`ScanReferenceError` (a ``ValueError``) saying why the scans cannot serve as a reference.

Two stages:

1. Correlative match (chefbot_navigation's :func:`~chefbot_navigation.slam.scan_matcher.match`):
   the ``after`` scan's hits against a likelihood field of the ``before`` scan's hits, over a
   window around the odometry's guess.  It finds the right basin even for a guess 0.5 rad or
   0.2 m off, and tells whether the best pose lies on the window's border (then it may be no
   maximum at all).  Its sub-cell refinement stops at 1/8 of a cell (2.5 mm at the default
   2 cm field), with a bias towards the field's blur: not enough for a 0.3 % distance.
2. Point-to-line ICP (Gauss-Newton, ``scipy.spatial.cKDTree``): each ``after`` hit against the
   line fitted through the ``before`` hits around its nearest neighbour (the neighbourhood's
   centroid and principal axis, which also averages the range noise of the reference scan).
   Its normal equations give the uncertainty and the conditioning: a scene that does not fix all
   three degrees of freedom (one flat wall: the motion along it) has a near-zero eigenvalue.

Heading: the scans only know the heading modulo 2 pi (after two full turns the room looks as it
did).  The result's yaw is the one closest to ``guess.yaw``, not wrapped: pass the odometry's
*total* turn (4 pi for two turns) and get e.g. 4 pi - 0.3.  This is right as long as the
odometry's heading error over the motion stays below pi (and inside the search window,
``Limits.window_yaw``); a larger one returns a yaw off by a multiple of 2 pi, or a refusal.

Scans: :class:`ScanData` holds a LaserScan's numbers (one scan, or several taken while standing
still, whose per-beam median halves the range noise of four) and the sensor's pose on the base,
so the result is the motion of the base, not of the sensor.
"""
from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_navigation.slam.scan import scan_from_ranges, transform_points
from chefbot_navigation.slam.scan_matcher import LikelihoodField, SearchWindow, match


class ScanReferenceError(ValueError):
    """The scans cannot give a reference motion; the message says why and what to change."""


@dataclass(frozen=True)
class ScanData:
    """A LaserScan's numbers, taken while the robot stood still.

    ``ranges`` (N,) m, REP 117 (``inf`` no return, NaN invalid), or (K, N) from K scans of the
    same standstill: their per-beam median is used (NaN and -inf dropped; +inf, no return, counts).  ``angle_min``,
    ``angle_increment`` rad, ``range_min``, ``range_max`` m as in the message;
    ``sensor_in_base``: the laser frame in the robot's base frame (m, rad).
    """

    ranges: np.ndarray
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    sensor_in_base: Pose2D = field(default_factory=Pose2D)

    def hits(self) -> np.ndarray:
        """(M, 2) m obstacle points in the base frame (beams with a valid in-range return)."""
        r = np.asarray(self.ranges, dtype=float)
        if r.ndim == 2:
            with np.errstate(invalid="ignore"):
                # NaN and -inf say nothing; +inf (no return) takes part: most scans without a return win
                finite = np.where(np.isnan(r) | (r == -np.inf), np.nan, r)
                if r.shape[0] == 0 or np.isnan(finite).all():
                    r = np.full(r.shape[1], np.nan)
                else:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", RuntimeWarning)   # all-NaN beams stay NaN
                        r = np.nanmedian(finite, axis=0)
        elif r.ndim != 1:
            raise ScanReferenceError(f"ranges must be (N,) or (K, N), got shape {r.shape}")
        scan = scan_from_ranges(r, self.angle_min, self.angle_increment, self.range_min, self.range_max,
                                self.sensor_in_base, self.range_max)
        return scan.hits

    def sees(self, pts: np.ndarray) -> np.ndarray:
        """(M,) bool: which (M, 2) points (base frame) lie in this scan's field of view and range."""
        local = transform_points(self.sensor_in_base.inverse(), pts)
        ang = np.arctan2(local[:, 1], local[:, 0])
        n = np.asarray(self.ranges).shape[-1]
        lo, hi = self.angle_min, self.angle_min + (n - 1) * self.angle_increment
        if hi - lo >= 2 * math.pi - 1e-6:
            in_fov = np.ones(len(local), dtype=bool)
        else:
            in_fov = (np.mod(ang - lo, 2 * math.pi) <= hi - lo)
        rng = np.hypot(local[:, 0], local[:, 1])
        return in_fov & (rng >= self.range_min) & (rng <= self.range_max)


@dataclass(frozen=True)
class Limits:
    """Search window and acceptance thresholds of :func:`relative_pose`.

    Window (around the guess): ``window_xy`` m + ``window_xy_per_m`` times the distance travelled;
    ``window_yaw`` rad + ``window_yaw_per_rad`` times the guessed turn (absolute, unwrapped).
    """

    min_beams: int = 40                  # hits needed in each scan
    window_xy: float = 0.10              # m
    window_xy_per_m: float = 0.05        # m per m travelled (odometry: a few %)
    window_yaw: float = 0.15             # rad
    window_yaw_per_rad: float = 0.05     # rad per rad of guessed turn (2 turns: +0.63 rad)
    min_score: float = 0.35              # correlative score (mean likelihood of the after hits)
    min_matched: float = 0.5             # fraction of after hits with a line of the before scan within the gate
    min_constraint: float = 0.005        # smallest eigenvalue of the normalised information (see ScanReference)
    max_sigma_xy: float = 0.01           # m, formal standard deviation of x or y
    max_sigma_yaw: float = math.radians(0.5)   # rad
    max_icp_shift: float = 0.06          # m, the ICP may move the correlative pose at most this far


# field of the correlative stage: cell (m), blur (m); the angle step is chosen from the scans' reach
FIELD_RES = 0.02
FIELD_SIGMA = 0.05
# ICP: neighbours of a reference hit for its line (count, radius m); a line thinner than this
# fraction of its length in std-dev terms; the gate on residuals (m, shrinks to GATE_SIGMAS x
# the robust residual std, not below GATE_MIN)
LINE_NEIGHBOURS = 48
LINE_RADIUS = 0.15
LINE_FLATNESS = 0.15
GATE_START = 0.08
GATE_MIN = 0.02
GATE_SIGMAS = 3.0
ICP_ITERATIONS = 50


@dataclass(frozen=True)
class ScanReference:
    """The robot's pose at ``after`` in the frame of the robot at ``before`` and its quality.

    ``pose`` m, rad (yaw unwrapped, the one nearest the guess); ``covariance`` (3, 3) in
    (x m, y m, yaw rad): the formal covariance of the ICP fit from its residuals, as if each
    beam were independent (neighbouring beams are not quite: read it as a lower bound; the unit
    tests measure the real scatter); ``sigma`` its diagonal's square roots.
    ``score``: correlative score (mean likelihood of the after hits, 0..1); ``matched``:
    fraction of the after hits that found a line of the before scan within the final gate;
    ``rms`` m residual of those; ``spread`` m the correlative matcher's spread (std-dev of the
    offsets scoring within 5 % of the best); ``constraint``: the smallest eigenvalue of the
    information matrix per matched beam with yaw scaled by the hits' rms range (0 = a direction
    the scene cannot fix, ~0.5 = normals evenly in all directions); ``beams``: matched hits.
    """

    pose: Pose2D
    covariance: np.ndarray
    score: float
    matched: float
    rms: float
    spread: float
    constraint: float
    beams: int

    @property
    def sigma(self) -> tuple[float, float, float]:
        """Standard deviations (x m, y m, yaw rad)."""
        d = np.sqrt(np.maximum(np.diag(self.covariance), 0.0))
        return float(d[0]), float(d[1]), float(d[2])


def relative_pose(before: ScanData, after: ScanData, guess: Pose2D, travelled: float | None = None,
                  limits: Limits | None = None) -> ScanReference:
    """Pose of the robot at ``after`` in the frame of the robot at ``before`` (m, rad).

    ``guess``: the odometry's estimate of the same motion, yaw unwrapped (the total turn);
    ``travelled`` m: the odometry's path length (a square's perimeter; default the guess's
    straight distance), which widens the search window for the position.  The
    result's yaw is the one within pi of ``guess.yaw``; the caller must keep the odometry's
    heading error over the motion below pi (the search only looks ``limits``' window around it).
    Raises :class:`ScanReferenceError` when a scan has too few hits, the best match lies on the
    border of the search window, the match is poor (score, matched fraction), the scene does not
    constrain all of x, y and yaw (e.g. a single flat wall), or the fit is too uncertain.
    """
    lim = limits or Limits()
    if not all(math.isfinite(v) for v in (guess.x, guess.y, guess.yaw)):
        raise ScanReferenceError(f"guess must be finite, got {guess}")
    ref = before.hits()
    cur = after.hits()
    for name, pts in (("before", ref), ("after", cur)):
        if len(pts) < lim.min_beams:
            raise ScanReferenceError(f"the {name} scan has {len(pts)} valid beams, fewer than {lim.min_beams}: "
                                     "is the sensor running and does it see walls or furniture in range?")

    # 1. correlative match around the guess (yaw wrapped for the matcher, unwrapped again below)
    dist = math.hypot(guess.x, guess.y) if travelled is None else float(travelled)
    if not (math.isfinite(dist) and dist >= 0.0):
        raise ScanReferenceError(f"travelled must be a finite distance >= 0 m, got {travelled}")
    reach = float(np.max(np.hypot(cur[:, 0], cur[:, 1])))
    window = SearchWindow(xy=lim.window_xy + lim.window_xy_per_m * dist,
                          yaw=lim.window_yaw + lim.window_yaw_per_rad * abs(guess.yaw),
                          yaw_step=min(math.radians(1.0), FIELD_RES / max(reach, 0.5)))
    lf = LikelihoodField(ref, FIELD_RES, sigma=FIELD_SIGMA, margin=window.xy + 0.5)
    prior = Pose2D(guess.x, guess.y, wrap_angle(guess.yaw))
    coarse = match(lf, cur, prior, window)
    if coarse.on_border:
        raise ScanReferenceError(
            f"the best match ({_fmt(coarse.pose)}) lies on the border of the search window (+-{window.xy:.2f} m, "
            f"+-{math.degrees(window.yaw):.0f} deg around the guess {_fmt(prior)}): the odometry's guess is too "
            "far off, or the scene repeats itself")
    if coarse.score < lim.min_score:
        raise ScanReferenceError(f"poor match: score {coarse.score:.2f} < {lim.min_score:.2f} (the scans share too "
                                 "little of the scene, or something moved between them)")

    # 2. point-to-line ICP from the correlative pose
    fit = _icp(ref, cur, coarse.pose)
    # judged on the after hits the before scan could have seen: a narrow sensor that ended a turn
    # 15 degrees short, or drove backwards, sees parts of the room the before scan did not
    visible = int(np.count_nonzero(before.sees(transform_points(fit.pose, cur))))
    if visible < lim.min_beams:
        raise ScanReferenceError(f"the scans share too little of the view: {visible} of the after scan's hits lie "
                                 f"where the before scan looked (< {lim.min_beams})")
    matched = min(1.0, fit.beams / visible)
    if matched < lim.min_matched:
        raise ScanReferenceError(f"poor match: only {matched:.0%} of the after scan's beams in the before scan's view "
                                 f"lie on one of its surfaces (< {lim.min_matched:.0%}); did something move?")
    if fit.constraint < lim.min_constraint:
        raise ScanReferenceError(
            f"the scene does not constrain the motion along {_direction(fit.weakest)} (constraint "
            f"{fit.constraint:.4f} < {lim.min_constraint}): a single flat wall or a corridor? "
            "Face a corner or furniture")
    shift = math.hypot(fit.pose.x - coarse.pose.x, fit.pose.y - coarse.pose.y)
    if shift > lim.max_icp_shift:
        raise ScanReferenceError(f"the fine fit moved {shift:.3f} m from the correlative match (> "
                                 f"{lim.max_icp_shift} m): no consistent match")
    sx, sy, syaw = (math.sqrt(max(v, 0.0)) for v in np.diag(fit.covariance))
    if max(sx, sy) > lim.max_sigma_xy or syaw > lim.max_sigma_yaw:
        raise ScanReferenceError(
            f"the fit is too uncertain: sigma x {sx * 1000:.1f} mm, y {sy * 1000:.1f} mm, yaw "
            f"{math.degrees(syaw):.2f} deg (limits {lim.max_sigma_xy * 1000:.1f} mm, "
            f"{math.degrees(lim.max_sigma_yaw):.2f} deg)")
    yaw = guess.yaw + wrap_angle(fit.pose.yaw - guess.yaw)
    return ScanReference(Pose2D(fit.pose.x, fit.pose.y, yaw), fit.covariance, float(coarse.score), matched,
                         fit.rms, float(coarse.spread), fit.constraint, fit.beams)


@dataclass
class _Fit:
    pose: Pose2D
    covariance: np.ndarray
    rms: float
    beams: int
    constraint: float
    weakest: np.ndarray


def _lines(pts: np.ndarray) -> tuple[cKDTree, np.ndarray, np.ndarray, np.ndarray]:
    """Tree over ``pts`` and, per point, the line through its neighbourhood: centroid (N, 2),
    unit normal (N, 2), and whether the neighbourhood is a line at all (N,) bool."""
    tree = cKDTree(pts)
    k = min(LINE_NEIGHBOURS, len(pts))
    d, idx = tree.query(pts, k=k, distance_upper_bound=LINE_RADIUS)
    d, idx = d.reshape(len(pts), k), idx.reshape(len(pts), k)
    w = np.isfinite(d).astype(float)                          # beyond the radius: index len(pts), weight 0
    nb = np.concatenate((pts, np.zeros((1, 2))))[idx]         # (N, k, 2)
    n = w.sum(axis=1)
    c = (nb * w[..., None]).sum(axis=1) / n[:, None]
    q = (nb - c[:, None, :]) * w[..., None]
    ev, vec = np.linalg.eigh(np.einsum("nki,nkj->nij", q, q) / n[:, None, None])   # ascending
    ok = (n >= 4) & (ev[:, 0] <= LINE_FLATNESS ** 2 * ev[:, 1])
    return tree, c, vec[:, :, 0], ok


def _icp(ref: np.ndarray, cur: np.ndarray, start: Pose2D) -> _Fit:
    """Point-to-line Gauss-Newton of ``cur`` (after hits, base frame) onto the lines of ``ref``.

    (A symmetric variant, before hits onto the after scan's lines too, measured no better on the
    synthetic scenes and made the formal covariance twice as optimistic.)"""
    lines = _lines(ref)
    x, y, th = start.x, start.y, start.yaw
    gate = GATE_START
    for _ in range(ICP_ITERATIONS):
        J, r, _p = _residuals(lines, cur, x, y, th, gate)
        if len(r) < 4:
            break
        try:
            delta = -np.linalg.solve(J.T @ J, J.T @ r)
        except np.linalg.LinAlgError:
            break
        # a scene that cannot fix a direction makes J'J near-singular: cap the step, the checks refuse it
        step = math.hypot(delta[0], delta[1])
        if step > gate:
            delta *= gate / step
        x, y, th = x + delta[0], y + delta[1], th + delta[2]
        # the gate shrinks to a few robust std-devs of the residuals (outliers: occlusions, new surfaces)
        gate_next = min(gate, max(GATE_MIN, GATE_SIGMAS * 1.4826 * float(np.median(np.abs(r)))))
        if step < 1e-6 and abs(delta[2]) < 1e-7 and gate_next == gate:
            break
        gate = gate_next
    J, r, p = _residuals(lines, cur, x, y, th, gate)
    m = len(r)
    if m < 4:
        return _Fit(Pose2D(x, y, th), np.full((3, 3), np.inf), math.inf, m, 0.0, np.array([1.0, 0.0, 0.0]))
    H = J.T @ J
    cov = float(r @ r) / (m - 3) * np.linalg.pinv(H)
    # conditioning: information per beam with yaw in metres at the hits' rms range (about the base)
    lever = max(float(np.sqrt(np.mean(np.sum((p - [x, y]) ** 2, axis=1)))), 0.1)
    S = np.diag([1.0, 1.0, 1.0 / lever])
    ev, vec = np.linalg.eigh(S @ H @ S / m)
    return _Fit(Pose2D(x, y, th), cov, math.sqrt(float(r @ r) / m), m, float(ev[0]), vec[:, 0])


def _residuals(lines: tuple[cKDTree, np.ndarray, np.ndarray, np.ndarray], cur: np.ndarray, x: float, y: float,
               th: float, gate: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Jacobian (M, 3) in (x, y, th) and point-to-line residuals (M,) m of the after hits within ``gate``
    of a line of the before scan, and those hits in the before frame (M, 2)."""
    tree, cen, nor, ok = lines
    c, s = math.cos(th), math.sin(th)
    rot = np.column_stack((c * cur[:, 0] - s * cur[:, 1], s * cur[:, 0] + c * cur[:, 1]))   # R p
    p = rot + [x, y]
    d, j = tree.query(p, distance_upper_bound=LINE_RADIUS)
    near = np.isfinite(d)
    j = np.where(near, j, 0)
    n = nor[j]
    r = np.einsum("ij,ij->i", p - cen[j], n)
    sel = near & ok[j] & (np.abs(r) < gate)
    n, rot = n[sel], rot[sel]
    # d(R p + t)/dt = I, d(R p)/dth = perp(R p) = (-(R p)_y, (R p)_x)
    J = np.column_stack((n[:, 0], n[:, 1], n[:, 1] * rot[:, 0] - n[:, 0] * rot[:, 1]))
    return J, r[sel], p[sel]


def _direction(v: np.ndarray) -> str:
    """The weak direction of the information matrix in words (v: (x, y, yaw scaled))."""
    if abs(v[2]) > 0.9:
        return "yaw (rotation)"
    t = v[:2] / max(float(np.hypot(v[0], v[1])), 1e-12)
    return f"the direction ({t[0]:+.2f}, {t[1]:+.2f}) in the before robot frame" + (
        "" if abs(v[2]) < 0.3 else " combined with a rotation")


def _fmt(p: Pose2D) -> str:
    return f"x {p.x:.3f} m, y {p.y:.3f} m, yaw {math.degrees(p.yaw):.1f} deg"
