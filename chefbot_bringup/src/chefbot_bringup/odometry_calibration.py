"""Odometry calibration: estimate ``ticks_meter`` (per wheel) and ``base_width`` from test drives.

Pure estimators (no rospy): the caller measures, these functions turn the measurements into the
parameters of :mod:`chefbot_bringup.odometry` and ``param/diff_drive.yaml``.  Conventions are
odometry.py's (REP 103): x forward, y left, yaw counter-clockwise positive; the left wheel sits at
+y.  The odometry computes wheel travel ``ticks / ticks_meter`` and heading changes
``(dr - dl) / base_width``; every factor below is derived from those two formulas.

Three procedures, meant to be done in this order, each with the results of the previous ones
loaded (the factors then simply multiply, :func:`calibrate`):

1. :func:`straight_line`: drive straight by odometry, measure with a tape -> ``ticks_meter``
   (the mean wheel scale).
2. :func:`in_place_turns` (optional, quick): turn on the spot N times by odometry, measure the
   turned angle (floor mark, IMU) -> ``base_width``.  Only the mean wheel scale enters an in-place
   turn, so unequal wheels do not disturb it.
3. :func:`umbmark`: Borenstein & Feng's UMBmark ("Measurement and correction of systematic
   odometry errors in mobile robots", IEEE Trans. Robotics and Automation 12(6), 1996): an
   L x L square driven by odometry clockwise and counter-clockwise n times each.  The end errors
   separate the two systematic errors of a differential drive: unequal wheel diameters (E_d, the
   robot curves on every side) and a wrong base width (E_b, every corner turns too far or too
   short).  Result: per-wheel ``ticks_meter`` and ``base_width``.

Step 1 measures the chord of the robot's path: with unequal wheels the robot curves, and the
chord is short of the travelled arc by about (heading change)^2 / 24 (0.3 % for 0.27 rad, i.e.
E_d 1.04 over 2 m).  With wheels that unequal repeat step 1 after step 3.
"""
from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import yaml
from scipy.optimize import least_squares

from chefbot_bringup.odometry import integrate_arc

# A correction outside this range is a set-up mistake, not a calibration: ticks_meter for 2X
# instead of 4X decoding is a factor 2, a yaw wrapped to +-pi or lengths in cm are worse.
PLAUSIBLE = (0.8, 1.25)
# A UMBmark run that stops farther from the start than this fraction of the side did not drive a
# square (or the errors are not in metres).  0.8 of the side is ~15 degrees of heading error per side;
# the exact model still fits that.  Wheels 4 % apart in diameter (+3 % / -1 %), which straight_line and
# in_place_turns cannot correct, already miss a 1 m square's start by 0.4-0.5 m.
MAX_END_ERROR_PER_SIDE = 0.8
# The fitted model must explain the centroids to within the largest of: this fraction of E_max,
# 3 standard errors of the centroids (from the scatter of the runs), RESIDUAL_FLOOR_M (a tape's
# resolution).  Otherwise the data do not describe the two systematic errors the model has.
RESIDUAL_FRACTION = 0.25
RESIDUAL_FLOOR_M = 0.002
FIT_BOUNDS = (0.5, 2.0)     # search range of E_d and E_b; PLAUSIBLE is checked afterwards

QUARTER = 0.5 * math.pi


def _finite(name: str, value: float) -> float:
    try:
        v = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if not math.isfinite(v):
        raise ValueError(f"{name} must be finite, got {value!r}")
    return v


def _positive(name: str, value: float) -> float:
    v = _finite(name, value)
    if v <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return v


def _plausible(name: str, factor: float, hint: str) -> float:
    if not PLAUSIBLE[0] <= factor <= PLAUSIBLE[1]:
        raise ValueError(f"{name} {factor:.4f} is outside the plausible {PLAUSIBLE[0]}..{PLAUSIBLE[1]}: {hint}")
    return factor


def straight_line(odom_distance_m: float, measured_distance_m: float) -> float:
    """Factor for ``ticks_meter`` from a straight drive: ``ticks_meter_new = ticks_meter * factor``.

    ``odom_distance_m``: the distance the odometry counted (m); ``measured_distance_m``: the distance
    the robot really moved (tape, m).  The ticks counted over the drive are ``odom * ticks_meter``,
    so the true ticks per metre are ``ticks_meter * odom / measured``.  A robot that counted
    1.00 m on 0.97 m of tape has wheels *smaller* than configured (less travel per tick) and
    gets 3.1 % more ticks per metre.
    """
    odom = _positive("odom_distance_m", odom_distance_m)
    measured = _positive("measured_distance_m", measured_distance_m)
    return _plausible("straight-line factor (odometry / tape)", odom / measured,
                      "ticks_meter for the other encoder decoding (2X: 14854, 4X: 29708)? lengths in "
                      "different units? the robot slipped or was stopped by hand?")


def in_place_turns(odom_yaw_rad: float, measured_yaw_rad: float) -> float:
    """Factor for ``base_width`` from turns on the spot: ``base_width_new = base_width * factor``.

    ``odom_yaw_rad``: the total (unwrapped) turning the odometry counted (rad); ``measured_yaw_rad``:
    the true total turning (floor mark or IMU, rad, same sign convention).  On the spot the
    wheels travel ``-s`` and ``+s``; odometry computes ``2 s / base_width``, the robot turns
    ``2 s / b_true``, hence ``b_true = base_width * odom / measured``: odometry counting 2 turns
    where the robot turned 2.06 gives a base 2.9 % narrower.  Record the turns with the
    straight-line ``ticks_meter`` already loaded (``s`` depends on it).
    """
    odom = _finite("odom_yaw_rad", odom_yaw_rad)
    measured = _finite("measured_yaw_rad", measured_yaw_rad)
    if odom == 0.0:
        raise ValueError("odom_yaw_rad must not be 0: the odometry counted no turning")
    if measured == 0.0:
        raise ValueError("measured_yaw_rad must not be 0: the reference saw no turning")
    if (odom > 0) != (measured > 0):
        raise ValueError(f"odom_yaw_rad {odom:.3f} and measured_yaw_rad {measured:.3f} have opposite signs: "
                         "both must count counter-clockwise positive")
    return _plausible("in-place turn factor (odometry / reference yaw)", odom / measured,
                      "was one of the yaws wrapped to +-pi? give the total turning of all turns "
                      "(N turns = N * 2 pi); degrees instead of radians?")


def wheel_factors(e_d: float) -> tuple[float, float]:
    """Borenstein's per-wheel travel factors ``(c_L, c_R)`` for the diameter ratio ``e_d`` (right/left).

    True wheel travel = ``c * travel counted with the common ticks_meter``; ``c_R / c_L = e_d`` and
    ``(c_L + c_R) / 2 = 1`` (the mean scale is step 1's business): ``c_L = 2 / (e_d + 1)``,
    ``c_R = 2 / (1 / e_d + 1)``.  Per-wheel ticks per metre: ``ticks_meter / c``.
    """
    e_d = _positive("e_d", e_d)
    return 2.0 / (e_d + 1.0), 2.0 / (1.0 / e_d + 1.0)


def square_end_error(side_m: float, base_width_m: float, e_d: float, e_b: float,
                     clockwise: bool) -> tuple[float, float]:
    """End error (m, m) of one UMBmark run that the model predicts: where the robot really stops,
    relative to its start, in the start frame (x forward, y left).

    The run: 4 times (a side of ``side_m`` m, a 90 degree turn on the spot), both by odometry
    with ``base_width_m``, so the robot believes it is back at the start facing the start
    direction.  The true robot: wheel travels scaled by :func:`wheel_factors` (``e_d``), base
    ``e_b * base_width_m``; every side is an exact arc, the corners include the small
    translation that unequal wheels cause on the spot.
    """
    c_l, c_r = wheel_factors(e_d)
    b_true = e_b * base_width_m
    wheel_turn = 0.5 * (-QUARTER if clockwise else QUARTER) * base_width_m   # right wheel, per corner
    pose = (0.0, 0.0, 0.0)
    for _ in range(4):
        pose = integrate_arc(*pose, c_l * side_m, c_r * side_m, b_true)
        pose = integrate_arc(*pose, -c_l * wheel_turn, c_r * wheel_turn, b_true)
    return pose[0], pose[1]


def umbmark_closed_form(cw_centroid: Sequence[float], ccw_centroid: Sequence[float], side_m: float,
                        base_width_m: float) -> tuple[float, float]:
    """``(E_d, E_b)`` from the mean end errors, first order in the heading errors (the fit's seed).

    Derived for our frames (not taken from the paper, whose axes differ): let ``a`` be the heading
    the robot gains on each side (rad, CCW positive; > 0 when the right wheel is larger) and ``g``
    what each corner falls short of 90 degrees (rad; > 0 when the true base is wider).  Side k
    (0..3) then starts with a heading error of ``k (a + g)`` clockwise and ``k (a - g)``
    counter-clockwise, and summing the sides' lateral offsets gives

        CW:  (x, y) = -2 L (a + g) (1, 1)        CCW: (x, y) = 2 L (a - g) (1, -1)

    so with ``A_cw = -(x_cw + y_cw) / 4L`` and ``A_ccw = (x_ccw - y_ccw) / 4L``:
    ``a = (A_cw + A_ccw) / 2``, ``g = (A_cw - A_ccw) / 2``.  A corner turns ``90 deg / E_b``, hence
    ``E_b = (pi/2) / (pi/2 - g)``; a side is an arc of radius ``R = L / a`` whose wheels, at
    ``+-b/2``, travel in the ratio ``E_d = (R + b/2) / (R - b/2) = (L + a b/2) / (L - a b/2)``.
    Its error is second order: ~1e-4 in E_d and E_b for 1 degree of heading error per side and a
    1 % base error, 1e-3 for 2.3 degrees (E_d 1.003 on a 4 m square with our 0.30 m base) or 4 %;
    the fit removes it.
    """
    x_cw, y_cw = cw_centroid
    x_ccw, y_ccw = ccw_centroid
    a_cw = -(x_cw + y_cw) / (4.0 * side_m)
    a_ccw = (x_ccw - y_ccw) / (4.0 * side_m)
    a, g = 0.5 * (a_cw + a_ccw), 0.5 * (a_cw - a_ccw)
    if g >= QUARTER:
        raise ValueError(f"the end errors mean corners of 90 - {math.degrees(g):.0f} degrees: not a square")
    e_b = QUARTER / (QUARTER - g)
    half = 0.5 * a * e_b * base_width_m
    if abs(half) >= side_m:
        raise ValueError(f"the end errors mean sides curved by {math.degrees(a):.0f} degrees: not a square")
    return (side_m + half) / (side_m - half), e_b


@dataclass(frozen=True)
class UmbmarkResult:
    """What :func:`umbmark` found.  Lengths in m."""

    e_d: float                  # wheel diameter ratio, right / left
    e_b: float                  # true base / base_width used for the runs
    c_left: float               # true left travel / counted travel (wheel_factors)
    c_right: float
    base_width: float           # corrected base width (m): e_b * base_width used
    base_width_used: float      # base_width the runs were driven with (m)
    side: float                 # side of the square (m)
    runs: int                   # runs per direction
    cw_centroid: tuple[float, float]
    ccw_centroid: tuple[float, float]
    e_max: float                # Borenstein's E_max,syst: the farther centroid from the start (m)
    fit_residual: float         # RMS of model minus centroids (m)
    closed_form: tuple[float, float]   # (E_d, E_b) of umbmark_closed_form, the fit's seed


def _runs(name: str, errors: Sequence[Sequence[float]]) -> np.ndarray:
    try:
        arr = np.asarray(errors, dtype=float)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a list of (x, y) end errors in m, got {errors!r}") from None
    if arr.size == 0:
        raise ValueError(f"{name} is empty: drive the square at least once that way (Borenstein: 5 times)")
    if arr.ndim != 2 or arr.shape[1] != 2:
        raise ValueError(f"{name} must be a list of (x, y) end errors in m, got shape {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise ValueError(f"{name} has a NaN or infinite end error: {errors!r}")
    return arr


def umbmark(cw_end_errors: Sequence[Sequence[float]], ccw_end_errors: Sequence[Sequence[float]],
            side_m: float, base_width_m: float) -> UmbmarkResult:
    """Wheel diameter ratio and base width from UMBmark runs (Borenstein & Feng 1996).

    Each run: the robot drives the square of :func:`square_end_error` by its own odometry
    (``ticks_meter`` from :func:`straight_line` loaded, ``base_width_m`` as configured);
    ``cw_end_errors`` / ``ccw_end_errors``: one ``(x, y)`` per run, the true stop position minus
    the start position (m), in the start frame: x along the start heading, y to the robot's left.
    (The opposite convention, start minus stop, flips both corrections: the fit cannot tell.)
    Clockwise runs turn right at every corner.  Same number of runs each way.

    Method: the closed form (:func:`umbmark_closed_form`) seeds a least-squares fit of
    ``(E_d, E_b)`` to the two centroids with the exact model (:func:`square_end_error`), which
    stays exact for robots that curve tens of degrees per side.  Raises ValueError if the data
    do not describe a square, do not fit the model (CW/CCW swapped, another frame, slip), or give
    an implausible correction.
    """
    cw = _runs("cw_end_errors", cw_end_errors)
    ccw = _runs("ccw_end_errors", ccw_end_errors)
    if len(cw) != len(ccw):
        raise ValueError(f"run the square the same number of times each way (Borenstein: 5): got {len(cw)} "
                         f"clockwise and {len(ccw)} counter-clockwise end errors")
    side = _positive("side_m", side_m)
    base = _positive("base_width_m", base_width_m)
    worst = float(np.max(np.hypot(*np.concatenate([cw, ccw]).T)))
    if worst > MAX_END_ERROR_PER_SIDE * side:
        raise ValueError(f"the square was not closed: end errors of {worst:.3g} m on a {side:.3g} m square "
                         "(errors in metres? driven by odometry with 90 degree turns? if the robot is this far "
                         "off, run straight_line and in_place_turns first, or use a smaller square)")
    c_cw, c_ccw = cw.mean(axis=0), ccw.mean(axis=0)
    target = np.concatenate([c_cw, c_ccw])
    closed = umbmark_closed_form(c_cw, c_ccw, side, base)
    seed = np.clip(closed, FIT_BOUNDS[0] + 1e-6, FIT_BOUNDS[1] - 1e-6)

    def residual(p: np.ndarray) -> np.ndarray:
        return np.concatenate([square_end_error(side, base, p[0], p[1], True),
                               square_end_error(side, base, p[0], p[1], False)]) - target

    fit = least_squares(residual, seed, bounds=FIT_BOUNDS, x_scale="jac", xtol=1e-14, ftol=1e-14, gtol=1e-14)
    e_d, e_b = (float(v) for v in fit.x)
    _plausible("E_d (right/left wheel diameter)", e_d,
               "the errors curve the sides far more than two wheels of one type can (CW and CCW swapped? "
               "errors not in the start frame, x forward and y left?)")
    _plausible("E_b (true/configured base width)", e_b,
               "the corners are far off 90 degrees (ticks_meter not calibrated? CW and CCW swapped?)")
    e_max = float(max(np.hypot(*c_cw), np.hypot(*c_ccw)))
    fit_residual = float(np.sqrt(np.mean(fit.fun ** 2)))
    noise = 0.0
    if len(cw) > 1:
        var = np.concatenate([cw.var(axis=0, ddof=1), ccw.var(axis=0, ddof=1)]) / len(cw)
        noise = float(np.sqrt(np.mean(var)))
    allowed = max(RESIDUAL_FRACTION * e_max, 3.0 * noise, RESIDUAL_FLOOR_M)
    if fit_residual > allowed:
        raise ValueError(f"the end errors do not fit unequal wheels plus a wrong base width: model residual "
                         f"{fit_residual:.3g} m for errors up to {e_max:.3g} m (allowed {allowed:.3g} m). "
                         "CW and CCW lists swapped? errors not in the start frame (x forward, y left)? "
                         "wheel slip or a bumpy floor?")
    c_l, c_r = wheel_factors(e_d)
    return UmbmarkResult(e_d=e_d, e_b=e_b, c_left=c_l, c_right=c_r, base_width=e_b * base, base_width_used=base,
                         side=side, runs=len(cw), cw_centroid=(float(c_cw[0]), float(c_cw[1])),
                         ccw_centroid=(float(c_ccw[0]), float(c_ccw[1])), e_max=e_max, fit_residual=fit_residual,
                         closed_form=(float(closed[0]), float(closed[1])))


@dataclass(frozen=True)
class Calibration:
    """Calibrated drive parameters, with the figures they came from (ticks/m, m)."""

    ticks_meter_left: float
    ticks_meter_right: float
    base_width: float
    ticks_meter_before: float
    base_width_before: float
    straight_factor: float = 1.0        # straight_line(): ticks_meter factor
    turn_factor: float = 1.0            # in_place_turns(): base_width factor
    umbmark: UmbmarkResult | None = None

    @property
    def ticks_meter(self) -> float:
        """The one ``ticks_meter`` for nodes without per-wheel values (ticks/m): the harmonic mean of
        the wheels', i.e. the same mean wheel travel (the arithmetic mean would stretch distances by
        (E_d + 1)^2 / 4 E_d)."""
        return 2.0 / (1.0 / self.ticks_meter_left + 1.0 / self.ticks_meter_right)

    def to_yaml(self) -> str:
        """The parameters under the keys of ``param/diff_drive.yaml``, with comments on how they were obtained."""
        lines = ["# Odometry calibration (chefbot_bringup odometry_calibration.py). Load this file after",
                 "# param/diff_drive.yaml (the later rosparam file wins) or copy the values into your copy of it.",
                 f"# before: ticks_meter {self.ticks_meter_before:.1f} ticks/m, "
                 f"base_width {self.base_width_before:.5f} m"]
        if self.straight_factor != 1.0:
            lines.append(f"# straight line: odometry / tape = {self.straight_factor:.5f} -> ticks_meter x that")
        if self.turn_factor != 1.0:
            lines.append(f"# in-place turns: odometry / reference yaw = {self.turn_factor:.5f} -> base_width x that")
        u = self.umbmark
        if u is not None:
            lines += [f"# UMBmark (Borenstein & Feng 1996): {u.runs} runs each way on a {u.side:.3f} m square;",
                      f"#   E_max before {u.e_max:.4f} m; E_d {u.e_d:.5f} (right/left wheel diameter), E_b {u.e_b:.5f}",
                      f"#   by least squares on the exact model (closed form: E_d {u.closed_form[0]:.5f}, "
                      f"E_b {u.closed_form[1]:.5f}); model residual {u.fit_residual * 1000:.1f} mm"]
        lines += [f"ticks_meter: {self.ticks_meter:.1f}        # [ticks/m] harmonic mean of the wheels below",
                  f"base_width: {self.base_width:.5f}          # [m] effective wheel separation",
                  "# per wheel: diff_tf takes each wheel's travel from its own, lwheel_pid / rwheel_pid",
                  "# (pid_velocity, ~side left / right) their wheel's; ticks_meter stays for the one-value readers",
                  "# (launchpad_node's encoder jump bound, bringup_check)",
                  f"ticks_meter_left: {self.ticks_meter_left:.1f}   # [ticks/m]",
                  f"ticks_meter_right: {self.ticks_meter_right:.1f}  # [ticks/m]"]
        return "\n".join(lines) + "\n"

    def save(self, path: str | Path) -> Path:
        """Write :meth:`to_yaml` to ``path``, creating its directory; returns the path."""
        p = Path(path)
        p.parent.mkdir(parents=True, exist_ok=True)
        p.write_text(self.to_yaml())
        return p


def load_calibration_yaml(existing: str | None) -> dict:
    """The mapping in a calibration YAML's text (None or blank: an empty one), to update and write back;
    ValueError if it is not a YAML mapping (a corrupt file is not to be overwritten)."""
    if existing is None or not existing.strip():
        return {}
    try:
        data = yaml.safe_load(existing)
    except yaml.YAMLError as exc:
        raise ValueError(f"not valid YAML ({exc}); fix or remove it") from None
    if not isinstance(data, dict):
        raise ValueError(f"not a YAML mapping but a {type(data).__name__}; fix or remove it")
    return data


def update_calibration_file(path: str | Path, merge: Callable[[str | None], str]) -> Path:
    """Rewrite the calibration YAML at ``path`` with ``merge(its text, or None if there is no file)``,
    creating its directory; the new text replaces the old in one rename, so an interrupted write
    leaves the old file. OSError from the file system, ValueError from ``merge`` (a corrupt file)."""
    p = Path(path)
    text = merge(p.read_text() if p.exists() else None)
    p.parent.mkdir(parents=True, exist_ok=True)
    tmp = p.with_name(p.name + ".tmp")
    tmp.write_text(text)
    tmp.replace(p)
    return p


def calibrate(ticks_meter: float, base_width: float, straight_factor: float = 1.0, turn_factor: float = 1.0,
              umbmark: UmbmarkResult | None = None) -> Calibration:
    """Combine the steps' results into new parameters.

    ``ticks_meter`` (ticks/m) and ``base_width`` (m): the values before calibration.  Each step is
    assumed to have been recorded with the previous steps' results loaded, so the factors
    multiply: ``ticks_meter * straight_factor / c`` per wheel, ``base_width * turn_factor * E_b``.
    """
    tm = _positive("ticks_meter", ticks_meter)
    base = _positive("base_width", base_width)
    straight_factor = _positive("straight_factor", straight_factor)
    turn_factor = _positive("turn_factor", turn_factor)
    tm_new, base_new = tm * straight_factor, base * turn_factor
    c_l = c_r = e_b = 1.0
    if umbmark is not None:
        if not math.isclose(umbmark.base_width_used, base_new, rel_tol=1e-6):
            raise ValueError(f"umbmark() was given base_width {umbmark.base_width_used:.5f} m but the steps before "
                             f"give {base_new:.5f} m: drive the squares with the calibrated base width loaded "
                             "and pass that one")
        c_l, c_r, e_b = umbmark.c_left, umbmark.c_right, umbmark.e_b
    return Calibration(ticks_meter_left=tm_new / c_l, ticks_meter_right=tm_new / c_r, base_width=base_new * e_b,
                       ticks_meter_before=tm, base_width_before=base, straight_factor=straight_factor,
                       turn_factor=turn_factor, umbmark=umbmark)
