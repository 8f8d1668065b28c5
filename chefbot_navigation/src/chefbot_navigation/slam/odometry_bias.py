"""Systematic wheel-odometry errors learned online from matched motion (pure).

A robot built from the book has wheels whose radius is a few per cent off the
value in ``ticks_meter``, a wheel base that is not the CAD value and wheels
that slip in spins.  Between two keyframes whose scans were both matched, the
matched motion is the truth the odometry should have reported; three factors
relate them:

* **distance scale** ``s_d``: matched distance / odometry distance, from every
  keyframe step of at least ``2 * delta`` whose match was well constrained
  (``spread`` ≤ ``calibration_max_spread``: a scan of a flat wall cannot say how far the robot
  went along it, and the matcher would just return the odometry's distance);
* **turn scale** ``s_t``: matched / odometry turn over in-place turns (< 2
  cells of motion, a turn of at least ``angularUpdate / 3``);
* **heading drift** ``k`` rad per metre driven forward, as the odometry counts
  metres (unequal wheel radii turn the robot slowly while the odometry says it
  drives straight): the matched heading change minus ``s_t`` times the
  odometry's, per metre, over steps that turned less than ``angularUpdate``;
* **from arcs** when there are not enough turns on the spot (a sparse log, one
  scan per 0.7 m / 25 deg, has almost none): every matched step's heading
  change is ``s_t * y + k * f`` for its odometry turn ``y`` and signed
  distance ``f``.  Two equations, one summed over the steps that turned
  (weighted by the sign of their turn), one over the steps that drove
  (weighted by the sign of their motion), give both at once, as long as the
  arcs do not all have the same curvature (then only ``s_t`` times it plus
  ``k`` is observable: the turn scale stays, the drift is learned given it).
  The turns on the spot are preferred where there are enough: on our recorded
  drives the arcs, whose turns the wheels slip through, taught a turn scale
  a few per cent lower and a map up to 5 cm worse.

Each is a ratio of sums over the accepted steps (consecutive steps' matching
errors cancel in the sums: what is left is the error at the ends of the
stretch), learned once enough motion has been seen (``turn_calibration_min``
rad, ``odometry_calibration_min`` m) and clipped to the configured limits.  A
step whose ratio is far from the current estimate (a slipped match, a wheel
spinning against a chair, a turn the wheels slipped through) is left out.

The distance scale and the drift are *applied* only once they leave a dead
band (``distance_scale_deadband``, ``drift_deadband``) and from then on.  Scan
matching against a map that ends just ahead of the robot is itself biased: new
beam ends beyond the mapped part score nothing, so poses a little short of the
truth score higher.  On the recorded hotel drive the matched steps add up to
0.9966 of the odometry's distance where the truth is 0.9981, and a learned
scale 0.2 % off the truth, applied, moved the offline map from 92.0 % to
81-94 % matched (the map's quality depends on it that sensitively).  Within the
dead band the matcher absorbs the bias as before; a wheel radius 3 % off
(a map bent beyond use) is far outside it.  The learned values are reported
either way (:func:`describe`, :func:`status`), and with
``odometry_calibration`` off they are learned and reported but never applied.

The corrected odometry step (:meth:`OdometryBias.correct`) is what the
front end predicts with, so the scan matcher's window starts near the truth,
blind stretches (no valid beams) drift less, and the map->odom correction the
SLAM publishes absorbs less error.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

from chefbot_common.geometry import Pose2D, wrap_angle

# a step whose implied scale or heading is this far off the current estimate is not used (a mis-match,
# the wheels turning while the robot is held, a turn the wheels slipped through): a real bias moves the
# ratios by a few per cent.  The heading's allowance: OUTLIER_HEADING + OUTLIER_TURN * |odometry turn| +
# OUTLIER_DRIFT * distance, that last at most OUTLIER_DRIFT_STEP
OUTLIER_SCALE = 0.25          # fraction
OUTLIER_HEADING = 0.03        # rad
OUTLIER_TURN = 0.2            # fraction of the odometry's turn
OUTLIER_DRIFT = 0.35          # rad per metre
OUTLIER_DRIFT_STEP = 0.05     # rad
HEADING_SPREAD = 3.0          # a driving step teaches the heading if matched within this x calibration_max_spread
MIN_CONDITION = 0.3           # the joint turn/drift solve needs det >= this x (sum |y|)(sum |f|) (1: independent)


@dataclass
class BiasLimits:
    """What :class:`OdometryBias` needs of ``SlamConfig`` (names as there)."""

    delta: float = 0.05
    angularUpdate: float = 0.15
    turn_calibration: bool = True
    turn_calibration_min: float = 6.0
    turn_scale_limit: float = 0.15
    odometry_calibration: bool = True
    odometry_calibration_min: float = 3.0
    distance_scale_limit: float = 0.15
    drift_limit: float = 0.1
    distance_scale_deadband: float = 0.01
    drift_deadband: float = 0.0087
    calibration_max_spread: float = 0.05


@dataclass
class BiasEstimate:
    """Learned factors (1, 1, 0 until enough motion was seen) and the evidence behind them."""

    distance_scale: float = 1.0         # true distance / odometry distance
    turn_scale: float = 1.0             # true turn / odometry turn
    drift_per_m: float = 0.0            # rad the robot turns per odometry metre driven forward that odometry misses
    distance_seen: float = 0.0          # m of matched odometry steps used for the scale and the drift
    turn_seen: float = 0.0              # rad of matched turning used for the turn scale
    distance_applied: bool = False      # the distance scale left its dead band: predictions use it
    drift_applied: bool = False         # the drift left its dead band: predictions use it


class OdometryBias:
    """Learns :class:`BiasEstimate` from matched keyframe steps and corrects odometry steps with it."""

    def __init__(self, limits: BiasLimits) -> None:
        self.lim = limits
        self.est = BiasEstimate()
        self._turn = [0.0, 0.0]        # in-place turning: (odometry, matched) rad
        self._dist = [0.0, 0.0]        # driving: (odometry, matched along the odometry's direction) m
        self._straight = [0.0, 0.0]    # straight-ish driving: (signed metres, heading change beyond s_t * y rad)
        # the two equations  s * Y + k * F = B  of the turn scale s and the drift k (module docstring):
        self._rows_t = [0.0, 0.0, 0.0]  # turning steps: sum |y|, sum sgn(y) f, sum sgn(y) dyaw
        self._rows_f = [0.0, 0.0, 0.0]  # driving steps: sum sgn(f) y, sum |f|, sum sgn(f) dyaw

    def correct(self, rel: Pose2D) -> Pose2D:
        """The odometry step ``rel`` (in the frame of its start) corrected by the learned factors."""
        e = self.est
        d = math.hypot(rel.x, rel.y)
        forward = math.copysign(d, rel.x) if d > 0 else 0.0
        scale = e.distance_scale if e.distance_applied else 1.0
        drift = e.drift_per_m if e.drift_applied else 0.0
        return Pose2D(rel.x * scale, rel.y * scale, rel.yaw * e.turn_scale + drift * forward)

    def observe(self, rel: Pose2D, matched: Pose2D, spread: float) -> None:
        """One step between two matched keyframes: ``rel`` the raw odometry step, ``matched`` the matched
        one (both in the frame of the step's start), ``spread`` (m) of the second match."""
        lim, e = self.lim, self.est
        d = math.hypot(rel.x, rel.y)
        dyaw = wrap_angle(matched.yaw)
        forward = math.copysign(d, rel.x) if d > 0 else 0.0
        turning = abs(rel.yaw) >= lim.angularUpdate / 3 and dyaw * rel.yaw > 0
        driving = d >= 2 * lim.delta
        if lim.turn_calibration and turning and d <= 2 * lim.delta:
            self._turn[0] += abs(rel.yaw)
            self._turn[1] += abs(dyaw)
        # the heading: a wall seen at an angle fixes it even where the position along the wall is unsure
        heading_ok = d <= 2 * lim.delta or spread <= HEADING_SPREAD * lim.calibration_max_spread
        expected = rel.yaw * e.turn_scale + e.drift_per_m * forward
        allowance = OUTLIER_HEADING + OUTLIER_TURN * abs(rel.yaw) + min(OUTLIER_DRIFT * d, OUTLIER_DRIFT_STEP)
        if heading_ok and abs(dyaw - expected) <= allowance:
            if turning:
                sg = math.copysign(1.0, rel.yaw)
                self._rows_t[0] += abs(rel.yaw)
                self._rows_t[1] += sg * forward
                self._rows_t[2] += sg * dyaw
            if driving:
                sg = math.copysign(1.0, forward)
                self._rows_f[0] += sg * rel.yaw
                self._rows_f[1] += abs(forward)
                self._rows_f[2] += sg * dyaw
                if abs(rel.yaw) < lim.angularUpdate and spread <= lim.calibration_max_spread:
                    self._straight[0] += forward
                    self._straight[1] += wrap_angle(dyaw - rel.yaw * e.turn_scale)
        if driving and spread <= lim.calibration_max_spread:
            along = (matched.x * rel.x + matched.y * rel.y) / d
            if abs(along / d - e.distance_scale) <= OUTLIER_SCALE:
                self._dist[0] += d
                self._dist[1] += along
                e.distance_seen = self._dist[0]
                if self._dist[0] >= lim.odometry_calibration_min:
                    e.distance_scale = _clip(self._dist[1] / self._dist[0], lim.distance_scale_limit)
                    e.distance_applied = lim.odometry_calibration and (
                        e.distance_applied or abs(e.distance_scale - 1.0) > lim.distance_scale_deadband)
        self._solve_heading()

    def _solve_heading(self) -> None:
        """Turn scale and drift: from the turns on the spot and the straight stretches where there are
        enough of them (each its own ratio, the errors at the ends only), else from all steps at once
        when they tell the two apart (a sparse log of arcs), else the drift given the turn scale."""
        lim, e = self.lim, self.est
        ty, tf, tb = self._rows_t
        fy, ff, fb = self._rows_f
        spins = lim.turn_calibration and self._turn[0] >= lim.turn_calibration_min
        e.turn_seen = self._turn[0]
        if spins:
            e.turn_scale = _clip(self._turn[1] / self._turn[0], lim.turn_scale_limit)
        if not (self._dist[0] >= lim.odometry_calibration_min and ff >= lim.odometry_calibration_min / 2):
            return
        det = ty * ff - tf * fy
        if lim.turn_calibration and not spins and ty >= lim.turn_calibration_min and det >= MIN_CONDITION * ty * ff:
            e.turn_scale = _clip((tb * ff - tf * fb) / det, lim.turn_scale_limit)
            e.turn_seen = ty
            k = (ty * fb - fy * tb) / det
        elif abs(self._straight[0]) >= lim.odometry_calibration_min / 2:
            k = self._straight[1] / self._straight[0]
        else:
            k = (fb - fy * e.turn_scale) / ff
        e.drift_per_m = max(-lim.drift_limit, min(lim.drift_limit, k))
        e.drift_applied = lim.odometry_calibration and (
            e.drift_applied or abs(e.drift_per_m) > lim.drift_deadband)


def _clip(ratio: float, limit: float) -> float:
    return max(1.0 - limit, min(1.0 + limit, ratio))


def describe(est: BiasEstimate) -> str:
    """One line for a user: what the learned factors say about the robot's odometry."""
    if est.distance_seen <= 0 and est.turn_seen <= 0:
        return "odometry bias: not learned yet (no matched motion)"
    parts = []
    if est.distance_seen > 0:
        off = (1.0 / est.distance_scale - 1.0) * 100 if est.distance_scale > 0 else float("nan")
        parts.append(f"distance scale {est.distance_scale:.4f} (wheel odometry counts {abs(off):.1f} % "
                     f"{'too far' if off > 0 else 'too short'}; learned from {est.distance_seen:.1f} m, "
                     f"{'applied' if est.distance_applied else 'within the dead band: not applied'})")
        side = "left" if est.drift_per_m > 0 else "right"
        parts.append(f"heading drift {math.degrees(abs(est.drift_per_m)):.2f} deg/m to the {side} "
                     f"({'applied' if est.drift_applied else 'within the dead band: not applied'})")
    if est.turn_seen > 0:
        off = (1.0 / est.turn_scale - 1.0) * 100 if est.turn_scale > 0 else float("nan")
        parts.append(f"turn scale {est.turn_scale:.4f} (odometry counts {abs(off):.1f} % "
                     f"{'too much' if off > 0 else 'too little'} turn; learned from "
                     f"{math.degrees(est.turn_seen):.0f} deg)")
    return "odometry bias: " + "; ".join(parts)


# /diagnostics level WARN beyond these: a bias this large bends maps and costs AMCL and the final heading at a
# table; the wheel radius (ticks_meter) or wheel base (base_width) in the robot's parameters should be fixed
WARN_SCALE = 0.02             # fraction
WARN_DRIFT = math.radians(1.0)  # rad per metre
WARN_TURN = 0.05              # fraction


def status(est: BiasEstimate) -> tuple[int, str, dict[str, str]]:
    """(diagnostic level 0 OK / 1 WARN, message, key values) of a learned bias, for ``/diagnostics``."""
    values = {"distance_scale": f"{est.distance_scale:.4f}", "turn_scale": f"{est.turn_scale:.4f}",
              "drift_deg_per_m": f"{math.degrees(est.drift_per_m):+.3f}",
              "distance_learned_m": f"{est.distance_seen:.1f}",
              "turn_learned_deg": f"{math.degrees(est.turn_seen):.0f}",
              "distance_applied": str(est.distance_applied), "drift_applied": str(est.drift_applied)}
    off = []
    if abs(est.distance_scale - 1.0) > WARN_SCALE:
        off.append("distance (wheel radius: ticks_meter)")
    if abs(est.drift_per_m) > WARN_DRIFT:
        off.append("straight-line heading (unequal wheels)")
    if abs(est.turn_scale - 1.0) > WARN_TURN:
        off.append("turns (wheel base: base_width)")
    if off:
        return 1, f"wheel odometry is off in {', '.join(off)}: calibrate it (docs/real-robot.md); " \
                  f"{describe(est)}", values
    return 0, describe(est), values
