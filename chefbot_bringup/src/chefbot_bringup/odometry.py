"""Differential-drive dead reckoning from wheel encoder ticks (core of ``diff_tf``).

Conventions (REP 103): x forward, y left, +theta counter-clockwise seen from
above; the left wheel sits at +y = base_width / 2, the right wheel at -y.

Kinematics (the book's chapter 2, equations 10-15, written from the
semantics): for wheel travel ``dl``, ``dr`` (m) over one update (each wheel's
ticks over its own ticks per metre: ``ticks_meter_left`` / ``ticks_meter_right``
for wheels of unequal diameter, else the shared ``ticks_meter``)

    d      = (dl + dr) / 2           distance of the base centre (m)
    dtheta = (dr - dl) / b           heading change (rad), b = base_width

If ``dtheta`` is (numerically) zero the base moved on a straight line;
otherwise it moved on a circle of signed radius R = d / dtheta about the
instantaneous centre of curvature ICC = (x - R sin(theta), y + R cos(theta)):

    x' = x + R (sin(theta + dtheta) - sin(theta))
    y' = y - R (cos(theta + dtheta) - cos(theta))
    theta' = theta + dtheta

The book's ``diff_tf`` moved the base along the chord with the heading at
the *start* of the step, i.e. with the wrong sign of the arc's lateral
offset; the exact arc above has no such error for any step length.

Time: every estimate carries the time ``t`` its encoder data describe (the caller passes the
arrival time of the reading, see :class:`TickPairer`), not the time it is published at, so
``tf`` users that look the pose up at a sensor's stamp (amcl at the scan stamp) get the pose
of that moment; an IMU sample is placed in time the same way (the wheels' turning after it
is added).  Stamping the publishing timer's time instead made tf ``odom → base_footprint``
lag the robot by ~50 ms: 5-7 degrees of heading in a 2 rad/s turn (README, ``diff_tf``).

Pose covariance is propagated with the usual linearised model: each wheel's
travel has variance ``k * |travel|`` (m^2, k = ``wheel_slip_var`` in m^2/m), so
the uncertainty grows with distance driven, never while standing still.
"""
from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, field

import numpy as np

from chefbot_bringup.encoder import EncoderRange, TickUnwrapper
from chefbot_common.geometry import wrap_angle

# Variance reported for the pose/twist components a planar robot cannot
# observe (z, roll, pitch): large so that filters ignore them.
UNOBSERVED_VAR = 1e6
WHEEL_HISTORY_S = 1.0   # s of wheel turning kept to place IMU samples in time (>> imu_delay)
# How far this process's clock may lag the encoder stream (a stalled host or, in sim, a /clock
# that reaches this node late: the ticks then run ahead of the time they are judged against).
# A jump that a lag this long explains is held back until the clock catches up, not dropped.
# 1 s: with two simulations on a loaded 2-core machine diff_tf's /clock fell ~0.7 s behind the firmware's
# ticks, and at 0.3 s the step was re-baselined: 0.2 m of travel lost, the robot's estimate 0.22 m off.
CLOCK_LAG_S = 1.0


def integrate_arc(x: float, y: float, theta: float, dl: float, dr: float,
                  base_width: float) -> tuple[float, float, float]:
    """Move the pose (m, m, rad) by wheel travels ``dl``, ``dr`` (m) on the exact arc.

    Written as the arc's chord (``d sin(h) / h``, h half the heading change) along the mean heading:
    the same arc as ``r (sin th1 - sin th0)``, without that form's cancellation for nearly straight
    steps (the odometry calibration's fit evaluates wheel ratios of 1 +- 1e-8)."""
    d = 0.5 * (dl + dr)
    half = 0.5 * (dr - dl) / base_width
    chord = d * math.sin(half) / half if half != 0.0 else d
    return x + chord * math.cos(theta + half), y + chord * math.sin(theta + half), theta + 2.0 * half


@dataclass(frozen=True)
class OdometryConfig:
    """Parameters of the dead-reckoning core."""

    ticks_meter: float = 14854.0      # encoder ticks per metre of wheel travel (ticks/m)
    ticks_meter_left: float | None = None    # ticks/m: the left wheel's own, for wheels of unequal diameter
                                             #   (unset: ticks_meter)
    ticks_meter_right: float | None = None   # ticks/m: the right wheel's own (unset: ticks_meter)
    base_width: float = 0.30          # distance between the wheel contact points (m)
    encoder: EncoderRange = field(default_factory=EncoderRange)
    max_wheel_speed: float = 0.377    # fastest physically possible wheel speed (m/s)
    wheel_slip_var: float = 1e-4      # wheel-travel variance per metre travelled (m^2/m)
    min_pose_var: float = 1e-6        # floor on x/y/yaw variance (m^2, rad^2)
    twist_linear_var: float = 1e-3    # variance of the reported linear speed ((m/s)^2)
    twist_angular_var: float = 1e-2   # variance of the reported yaw rate ((rad/s)^2)
    imu_timeout: float = 0.25         # s: an IMU yaw older than this is stale, the wheels give the heading
    twist_window: float = 0.1         # s: the reported speeds average the steps of at least this span
    imu_delay: float = 0.0            # s: an IMU yaw describes its arrival time minus this (sensor + line latency)

    def __post_init__(self) -> None:
        for name in ("ticks_meter", "base_width", "max_wheel_speed", "imu_timeout", "twist_window"):
            if not (getattr(self, name) > 0 and math.isfinite(getattr(self, name))):
                raise ValueError(f"{name} must be a positive finite number, got {getattr(self, name)!r}")
        for name in ("ticks_meter_left", "ticks_meter_right"):   # unequal wheels (the calibration's E_d)
            v = getattr(self, name)
            if v is not None and (isinstance(v, bool) or not isinstance(v, (int, float))
                                  or not (v > 0 and math.isfinite(v))):
                raise ValueError(f"{name} must be a positive finite number (ticks/m) or unset, got {v!r}")
        for name in ("wheel_slip_var", "min_pose_var", "twist_linear_var", "twist_angular_var"):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name} must be >= 0, got {getattr(self, name)!r}")
        if not 0.0 <= self.imu_delay < min(self.imu_timeout, WHEEL_HISTORY_S):
            raise ValueError(f"imu_delay must be >= 0 s and below imu_timeout ({self.imu_timeout} s), "
                             f"got {self.imu_delay!r}")

    @property
    def wheel_ticks_meter(self) -> tuple[float, float]:
        """Ticks per metre of the (left, right) wheel: each wheel's own value, else ``ticks_meter``."""
        return (float(self.ticks_meter if self.ticks_meter_left is None else self.ticks_meter_left),
                float(self.ticks_meter if self.ticks_meter_right is None else self.ticks_meter_right))


@dataclass
class OdometryState:
    """One odometry estimate: pose (m, m, rad), twist (m/s, rad/s), covariances."""

    t: float
    x: float
    y: float
    theta: float
    v: float
    w: float
    pose_cov: np.ndarray    # 6x6, order x y z roll pitch yaw (nav_msgs convention)
    twist_cov: np.ndarray   # 6x6


class DiffOdometry:
    """Integrate cumulative wheel ticks into a planar pose.

    Feed the latest raw counters with :meth:`set_ticks` (any rate), then call
    :meth:`update` at the publishing rate with the current time.  A counter
    jump that no wheel could have driven (board reset, lost messages during a
    reconnect) re-baselines instead of teleporting the robot; the number of
    such events is in :attr:`resets`.  A jump that a late clock explains
    (up to ``CLOCK_LAG_S``) is held back first, and integrated whole once the
    clock has caught up (:attr:`held`: such steps).
    """

    def __init__(self, cfg: OdometryConfig) -> None:
        self.cfg = cfg
        self._tpm_l, self._tpm_r = cfg.wheel_ticks_meter   # ticks/m per wheel
        self._left = TickUnwrapper(cfg.encoder)
        self._right = TickUnwrapper(cfg.encoder)
        self._pos_l: int | None = None      # latest unwrapped positions (ticks)
        self._pos_r: int | None = None
        self._base_l: int | None = None     # positions at the last integration (ticks)
        self._base_r: int | None = None
        self._t_last: float | None = None
        self._yaw_imu: float | None = None
        self._yaw_imu_t: float | None = None       # when the latest IMU yaw arrived (s)
        self._imu_seq = 0                          # IMU samples received
        self._yaw_imu_base: float | None = None    # the IMU yaw the heading is anchored to ...
        self._imu_base_seq = 0                     # ... which sample that was
        self._wheel_since_imu = 0.0                # wheel turning (rad) added since that sample
        self.imu_used = False                      # the last step's heading was anchored to the IMU
        self.x = self.y = self.theta = 0.0
        self.v = self.w = 0.0
        self.resets = 0
        self.held = 0
        self._hold_since: float | None = None       # when the current held-back jump was first seen (s)
        self._p = np.diag([cfg.min_pose_var] * 3)   # x, y, theta covariance
        # (t, distance, heading) accumulated, over the last twist_window: the reported speeds
        self._travel: deque[tuple[float, float, float]] = deque()
        # (t, cumulative wheel turning rad) of the last WHEEL_HISTORY_S: places IMU samples in time
        self._wheel_hist: deque[tuple[float, float]] = deque()

    def set_ticks(self, left: int | None = None, right: int | None = None) -> None:
        """Record the latest raw cumulative counters (ticks); ``None`` leaves a wheel unchanged."""
        if left is not None:
            self._pos_l = self._left.update(left)
        if right is not None:
            self._pos_r = self._right.update(right)

    def set_imu_yaw(self, yaw: float, t: float | None = None) -> None:
        """Record the latest IMU yaw (rad) received at ``t`` (s); while it is fresh (younger than
        ``imu_timeout`` at each update), heading changes come from it, else from the wheels.
        ``t`` None: always fresh (a caller that checks the age itself)."""
        self._yaw_imu = yaw
        self._yaw_imu_t = t
        self._imu_seq += 1

    def _wheel_turn_since(self, t_sample: float | None) -> float:
        """Wheel turning (rad) from ``t_sample`` (s) to the newest reading, interpolated in the recent
        history of the wheels' cumulative turning (0 for a sample without a time: it describes now)."""
        if t_sample is None or len(self._wheel_hist) < 2:
            return 0.0
        ts, cum = zip(*self._wheel_hist, strict=True)
        return cum[-1] - float(np.interp(t_sample, ts, cum))

    def _imu_fresh(self, t: float) -> bool:
        return self._yaw_imu is not None and (self._yaw_imu_t is None or
                                              t - self._yaw_imu_t <= self.cfg.imu_timeout)

    def _rebaseline(self, t: float) -> None:
        self._base_l, self._base_r = self._pos_l, self._pos_r
        self._hold_since = None
        self._travel.clear()
        self._wheel_hist.clear()
        self._wheel_hist.append((t, 0.0))
        self._anchor_imu(t)

    def _anchor_imu(self, t: float) -> None:
        """Anchor the heading to the current IMU sample (none if it is stale)."""
        self._yaw_imu_base = self._yaw_imu if self._imu_fresh(t) else None
        self._imu_base_seq, self._wheel_since_imu = self._imu_seq, 0.0

    def update(self, t: float) -> OdometryState | None:
        """Integrate the travel since the last call; ``t`` in seconds.

        Returns ``None`` until both wheels have reported once.
        """
        if self._pos_l is None or self._pos_r is None:
            return None
        if self._base_l is None or self._t_last is None:
            self._rebaseline(t)
            self._t_last = t
            return self.state(t)
        dt = t - self._t_last
        # dt == 0: the same clock reading as the last step (a sim's /clock is coarser than the
        # encoder lines when it runs faster than real time) is still a step: its travel counts
        # (re-baselining here lost every such line's travel, 32 % of it at 4.6x).
        if dt < 0.0:
            # Time went backwards (sim time reset): re-baseline.
            self._rebaseline(t)
            self._t_last = t
            return self.state(t)
        cfg = self.cfg
        dl = (self._pos_l - self._base_l) / self._tpm_l
        dr = (self._pos_r - self._base_r) / self._tpm_r
        # A wheel cannot travel farther than max speed allows (50 % margin plus
        # a couple of cm for message jitter): anything bigger is a counter
        # reset or garbage, so take the new counters as the baseline.
        limit = 1.5 * cfg.max_wheel_speed * dt + 0.02
        jump = max(abs(dl), abs(dr))
        if jump > limit:
            # A late clock: the ticks ran ahead of this clock, which catches up within CLOCK_LAG_S;
            # nothing is integrated meanwhile (baseline and time kept), then the travel counts whole.
            # (Dropping such steps lost 39 of them, several cm each, in an uncapped sim on 2 cores.)
            lag_limit = 1.5 * cfg.max_wheel_speed * (dt + CLOCK_LAG_S) + 0.02
            if self._hold_since is None:
                self._hold_since = t
            if jump <= lag_limit and t - self._hold_since <= CLOCK_LAG_S:
                self.held += 1
                return self.state(t)
            self.resets += 1
            self._rebaseline(t)
            self._t_last = t
            self.v = self.w = 0.0
            return self.state(t)
        self._hold_since = None

        d = 0.5 * (dl + dr)
        wheel_dtheta = (dr - dl) / cfg.base_width
        self._wheel_hist.append((t, self._wheel_hist[-1][1] + wheel_dtheta if self._wheel_hist else wheel_dtheta))
        while self._wheel_hist[0][0] < t - WHEEL_HISTORY_S:
            self._wheel_hist.popleft()
        # Heading from the IMU: on a new sample, the IMU's turn since the anchor sample minus what
        # the wheels already added in between; between samples the wheels bridge (and are corrected
        # by the next sample), so a late or lost sample loses no turning.  A stale IMU (silent for
        # imu_timeout) hands the heading to the wheels until a sample re-anchors it.
        self.imu_used = self._imu_fresh(t) and self._yaw_imu_base is not None
        if self.imu_used and self._imu_seq != self._imu_base_seq:
            # the sample's turn since the anchor, plus the wheels' turning after the sample's time
            # (its arrival minus imu_delay): the heading then describes t, as the position does
            after = self._wheel_turn_since(None if self._yaw_imu_t is None else self._yaw_imu_t - cfg.imu_delay)
            dtheta = wrap_angle(self._yaw_imu - self._yaw_imu_base) - self._wheel_since_imu + after
            self._yaw_imu_base, self._imu_base_seq, self._wheel_since_imu = self._yaw_imu, self._imu_seq, after
        elif self.imu_used:
            dtheta = wheel_dtheta
            self._wheel_since_imu += wheel_dtheta
        else:
            dtheta = wheel_dtheta
            self._anchor_imu(t)
        # Split the heading change into wheel travels so the arc formula stays the single source
        # of truth.
        half = 0.5 * dtheta * cfg.base_width
        dl_eff, dr_eff = d - half, d + half

        self._propagate_cov(d, dtheta, dl, dr)
        self.x, self.y, th = integrate_arc(self.x, self.y, self.theta, dl_eff, dr_eff, cfg.base_width)
        self.theta = wrap_angle(th)
        self.v, self.w = self._twist(t, d, dtheta)
        self._base_l, self._base_r = self._pos_l, self._pos_r
        self._t_last = t
        return self.state(t)

    def _twist(self, t: float, d: float, dtheta: float) -> tuple[float, float]:
        """Speeds (m/s, rad/s) over the steps of the last ``twist_window`` s (at least one step):
        steps at the board's line rate (30 Hz) timed by arrival would make single-step speeds jitter."""
        if not self._travel:
            self._travel.append((self._t_last, 0.0, 0.0))
        _, dist0, head0 = self._travel[-1]
        self._travel.append((t, dist0 + d, head0 + dtheta))
        while len(self._travel) > 2 and t - self._travel[1][0] >= self.cfg.twist_window:
            self._travel.popleft()
        t0, dist0, head0 = self._travel[0]
        _, dist1, head1 = self._travel[-1]
        if t <= t0:   # only steps on one clock reading so far: no speed to tell yet
            return self.v, self.w
        return (dist1 - dist0) / (t - t0), (head1 - head0) / (t - t0)

    def _propagate_cov(self, d: float, dtheta: float, dl: float, dr: float) -> None:
        """First-order covariance propagation for one step (midpoint heading)."""
        cfg = self.cfg
        m = self.theta + 0.5 * dtheta
        c, s = math.cos(m), math.sin(m)
        f = np.array([[1.0, 0.0, -d * s], [0.0, 1.0, d * c], [0.0, 0.0, 1.0]])
        # Noise in wheel space, mapped to (d, dtheta) then to (x, y, theta).
        q_wheels = np.diag([cfg.wheel_slip_var * abs(dl), cfg.wheel_slip_var * abs(dr)])
        b = cfg.base_width
        j = np.array([[0.5, 0.5], [-1.0 / b, 1.0 / b]])
        g = np.array([[c, -0.5 * d * s], [s, 0.5 * d * c], [0.0, 1.0]])
        gj = g @ j
        self._p = f @ self._p @ f.T + gj @ q_wheels @ gj.T

    def state(self, t: float) -> OdometryState:
        """Current estimate as an :class:`OdometryState` (covariances as 6x6)."""
        cfg = self.cfg
        pose_cov = np.diag([0.0, 0.0, UNOBSERVED_VAR, UNOBSERVED_VAR, UNOBSERVED_VAR, 0.0])
        idx = [0, 1, 5]
        pose_cov[np.ix_(idx, idx)] = self._p + np.eye(3) * cfg.min_pose_var
        twist_cov = np.diag([cfg.twist_linear_var, cfg.twist_linear_var, UNOBSERVED_VAR,
                             UNOBSERVED_VAR, UNOBSERVED_VAR, cfg.twist_angular_var])
        return OdometryState(t, self.x, self.y, self.theta, self.v, self.w, pose_cov, twist_cov)


def silent_encoders(last_ticks: dict[str, float | None], t: float, timeout: float) -> str:
    """Which wheel topics are older than ``timeout`` s at time ``t`` (s), e.g.
    ``'lwheel 1.2 s ago, rwheel 1.2 s ago'``; '' while all are fresh, before every wheel has
    reported once (odometry has nothing to publish then anyway) or with ``timeout`` 0 (off).
    ``last_ticks``: topic -> when it last reported (s).  diff_tf withholds odom and tf while
    this is non-empty: odometry from frozen counters would claim the robot stands still."""
    if timeout <= 0 or any(v is None for v in last_ticks.values()):
        return ""
    return ", ".join(f"{k} {t - v:.1f} s ago" for k, v in last_ticks.items() if t - v > timeout)


class TickPairer:
    """Pair the two wheels' readings of one encoder line and give the pair its time.

    The driver publishes each board line's counters as two unstamped messages (``lwheel``,
    ``rwheel``: std_msgs/Int32, as the book's), one after the other.  :meth:`add` collects them;
    once both wheels have reported since the last pair it returns ``(left, right, t)``, ``t``
    being the earlier of the two arrival times (s): the closest to when the board read the
    counters that an unstamped message can tell.  A wheel reporting twice before the other (a
    lost message) keeps its newer reading.
    """

    def __init__(self) -> None:
        self._left: tuple[int, float] | None = None
        self._right: tuple[int, float] | None = None

    def add(self, t: float, left: int | None = None, right: int | None = None) -> tuple[int, int, float] | None:
        """Record a reading (raw ticks) that arrived at ``t`` s; the completed pair, or None."""
        if left is not None:
            self._left = (left, t)
        if right is not None:
            self._right = (right, t)
        if self._left is None or self._right is None:
            return None
        (lv, lt), (rv, rt) = self._left, self._right
        self._left = self._right = None
        return lv, rv, min(lt, rt)
