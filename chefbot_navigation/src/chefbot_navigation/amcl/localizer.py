"""AMCL's update logic around the particle filter (pure: no rospy, time in float s).

:class:`Amcl` gets the map, scans (ranges + the scan frame's pose in the base
frame) with the odometry pose of the base at the scan's stamp, and keeps
``map -> odom``.  As ROS's amcl:

* the filter moves and weighs only after the odometry changed by more than
  ``update_min_d`` (m, in x or y) or ``update_min_a`` (rad) since the last
  update, or when forced (first scan, new initial pose, global localization,
  ``request_nomotion_update``); resampling every ``resample_interval`` updates;
* the pose estimate is the heaviest cluster's mean, the covariance that of the
  whole set, both taken after weighing and before resampling;
* ``map_T_odom = map_T_base · (odom_T_base)⁻¹`` with both at the scan stamp.

Without scans the odometry still moves the particles (``predict_only``), so the
covariance grows as the robot drives blind.  :meth:`Amcl.diagnostics` reports
the spread, the mean beam fit and the age of the last scan.
"""
from __future__ import annotations

import math
import time
from collections import deque
from dataclasses import dataclass

import numpy as np

from chefbot_common.geometry import Pose2D, map_to_odom, wrap_angle
from chefbot_common.grid import OccupancyMap
from chefbot_navigation.amcl.filter import FilterConfig, ParticleFilter
from chefbot_navigation.amcl.motion import DiffMotionNoise
from chefbot_navigation.amcl.sensor import LaserModel, LikelihoodField, MapError, points_before, select_beams

OK, WARN, ERROR = 0, 1, 2   # diagnostic_msgs/DiagnosticStatus levels


@dataclass(frozen=True)
class AmclConfig:
    """Every parameter of the node, named as ROS's amcl (ours: marked). Units m, rad, s, Hz."""

    min_particles: int = 500            # [particles] fewest the KLD resampling keeps (a converged set shrinks to
                                        # this); 1 <= min_particles <= max_particles
    max_particles: int = 2000           # [particles] set size after (re)initialisation and the KLD cap; more: slower
                                        # updates, more hypotheses kept (<= global_samples)
    kld_err: float = 0.05
    kld_z: float = 0.99
    update_min_d: float = 0.25          # m
    update_min_a: float = 0.2           # rad
    resample_interval: int = 1
    recovery_alpha_slow: float = 0.01
    recovery_alpha_fast: float = 0.1
    odom_model_type: str = "diff"       # odometry motion model: diff (differential drive, motion.py); diff-corrected
                                        # is accepted and runs the same model
    odom_alpha1: float = 0.2
    odom_alpha2: float = 0.2
    odom_alpha3: float = 0.2
    odom_alpha4: float = 0.2
    laser_model_type: str = "likelihood_field"  # laser model; only likelihood_field is implemented
    laser_max_beams: int = 60           # at most this many valid beams of a scan weigh the particles, evenly spaced
                                        # (>= 2); more: slower updates
    laser_min_range: float = -1.0       # m, <= 0: the scan's range_min
    laser_max_range: float = -1.0       # m, <= 0: the scan's range_max
    laser_z_hit: float = 0.5            # weight of the hit term, a Gaussian around the nearest obstacle (>= 0)
    laser_z_rand: float = 0.5           # weight of the random-reading term, uniform z_rand / range_max (>= 0; not
                                        # both 0)
    laser_sigma_hit: float = 0.2        # [m] std-dev of the hit Gaussian: how far a beam end may lie from an
                                        # obstacle and still fit (scan noise plus map blur)
    laser_likelihood_max_dist: float = 2.0  # m
    occupied_threshold: int = 65        # ours: map values >= this are obstacles
    laser_through_dist: float = 0.0     # [m] ours: a beam whose point this far before its end lies inside an
                                        # obstacle went through it (sensor.py); 0: off, as amcl
    initial_pose_x: float = 0.0         # [m] x of the initial pose in global_frame_id (save_pose_rate updates it)
    initial_pose_y: float = 0.0         # [m] y of the initial pose in global_frame_id
    initial_pose_a: float = 0.0         # [rad] yaw of the initial pose in global_frame_id
    initial_cov_xx: float = 0.25        # [m²] variance of the initial pose's x (>= 0)
    initial_cov_yy: float = 0.25        # [m²] variance of the initial pose's y (>= 0)
    initial_cov_aa: float = (math.pi / 12.0) ** 2  # [rad²] variance of the initial pose's yaw (>= 0)
    transform_tolerance: float = 1.0    # s, future-dating of map->odom and max age of odometry
    save_pose_rate: float = 0.5         # Hz, last pose to the parameter server (<= 0 off)
    gui_publish_rate: float = 10.0      # Hz, particlecloud (<= 0: every update)
    global_frame_id: str = "map"        # map frame: parent of the published map->odom, frame of amcl_pose and
                                        # particlecloud; initialpose must be given in it
    odom_frame_id: str = "odom"         # odometry frame: odom->base is read from tf, map->odom published
    base_frame_id: str = "base_footprint"  # robot frame: child of odom->base; scans are placed relative to it
    tf_broadcast: bool = True           # publish map->odom (false: amcl_pose only, when another node owns map->odom)
    use_map_topic: bool = False
    first_map_only: bool = False
    seed: int = 0                       # ours: random generator seed (same inputs, same run)
    global_samples: int = 50000         # ours: poses scored at the first update after global localization
    recovery_pool: int = 25             # ours: scored candidates per injected particle (1 = amcl's blind draw)
    recovery_scans: int = 20            # [scans] ours: recent scans (odometry-aligned) the candidates are scored on
    recovery_beams: int = 180           # ours: at most this many of those scans' beams
    recovery_refine: int = 4            # ours: jittered copies per chosen candidate, scored again (0: none)
    estimate_switch_ratio: float = 3.0  # ours: another cluster must be this many times heavier to become the
                                        # estimate (1: always the heaviest, as amcl)
    estimate_min_gain: float = 0.0      # ours: ... and fit the recent scans this much better (0: weight alone)
    recovery_max_fit: float = 0.7       # ours: no recovery injection while the mean beam fit is at least this
                                        # (1: amcl, the alphas alone)
    recovery_poor_fit_rate: float = 0.0  # ours: while no particle's mean beam fit reaches recovery_max_fit, at least
                                        # this fraction of the set is injected per resampling (0: amcl, the alphas
                                        # alone)
    scan_timeout: float = 1.0           # ours: s since the last scan came (its arrival, not its stamp) before the node
                                        # says so and moves the particles by odometry alone
    spread_warn: float = 0.5            # ours: m, position stddev above which diagnostics warn
    fit_warn: float = 0.5               # ours: mean beam fit (0..1) below which diagnostics warn

    def __post_init__(self) -> None:
        if self.odom_model_type not in ("diff", "diff-corrected"):
            raise ValueError(f"odom_model_type must be diff (or diff-corrected), got {self.odom_model_type!r}")
        if self.laser_model_type != "likelihood_field":
            raise ValueError(f"laser_model_type must be likelihood_field, got {self.laser_model_type!r}")
        if not (self.update_min_d >= 0 and self.update_min_a >= 0):
            raise ValueError("update_min_d and update_min_a must be >= 0")
        if self.resample_interval < 1:
            raise ValueError(f"resample_interval must be >= 1, got {self.resample_interval}")
        if self.global_samples < self.max_particles:
            raise ValueError(f"global_samples must be >= max_particles, got {self.global_samples}")
        if self.laser_max_beams < 2:
            raise ValueError(f"laser_max_beams must be >= 2, got {self.laser_max_beams}")
        if not (self.initial_cov_xx >= 0 and self.initial_cov_yy >= 0 and self.initial_cov_aa >= 0):
            raise ValueError("initial_cov_xx, initial_cov_yy and initial_cov_aa must be >= 0")
        if not 0.0 <= self.transform_tolerance <= 10.0:
            raise ValueError(f"transform_tolerance must be in [0, 10] s, got {self.transform_tolerance}")
        if not self.scan_timeout > 0:
            raise ValueError(f"scan_timeout must be > 0 s, got {self.scan_timeout}")
        for name in ("global_frame_id", "odom_frame_id", "base_frame_id"):
            if not getattr(self, name):
                raise ValueError(f"{name} must be a non-empty frame name")
        self.filter_config()
        self.motion_noise()
        self.laser_model()

    def filter_config(self) -> FilterConfig:
        """The particle filter's settings (particle counts, KLD, recovery)."""
        return FilterConfig(self.min_particles, self.max_particles, self.kld_err, self.kld_z,
                            self.recovery_alpha_slow, self.recovery_alpha_fast, self.recovery_pool,
                            self.recovery_scans, self.recovery_beams, self.recovery_refine,
                            self.estimate_switch_ratio, self.recovery_max_fit,
                            self.estimate_min_gain, self.recovery_poor_fit_rate)

    def motion_noise(self) -> DiffMotionNoise:
        """The odometry motion model's noise (odom_alpha1..4)."""
        return DiffMotionNoise(self.odom_alpha1, self.odom_alpha2, self.odom_alpha3, self.odom_alpha4)

    def laser_model(self) -> LaserModel:
        """The likelihood-field laser model's settings."""
        return LaserModel(self.laser_z_hit, self.laser_z_rand, self.laser_sigma_hit,
                          self.laser_likelihood_max_dist, self.occupied_threshold, self.laser_through_dist)

    def initial_cov(self) -> np.ndarray:
        """Covariance (x m^2, y m^2, yaw rad^2) of the initial pose as a 3 x 3 array."""
        return np.diag([self.initial_cov_xx, self.initial_cov_yy, self.initial_cov_aa])


@dataclass(frozen=True)
class Estimate:
    """Pose of the base in the map (m, rad), its covariance 3x3 (x, y, yaw), stamp (s)."""

    pose: Pose2D
    cov: np.ndarray
    stamp: float

    @property
    def spread(self) -> float:
        """Position stddev (m): sqrt of the larger eigenvalue of the x-y covariance."""
        return float(math.sqrt(max(np.linalg.eigvalsh(self.cov[:2, :2]).max(), 0.0)))


class Amcl:
    """Monte Carlo localization with amcl's interface semantics."""

    def __init__(self, cfg: AmclConfig) -> None:
        self.cfg = cfg
        self.rng = np.random.default_rng(cfg.seed)
        self.noise = cfg.motion_noise()
        self.pf = ParticleFilter(cfg.filter_config(), self.rng)
        self.field: LikelihoodField | None = None
        self.pending: tuple[Pose2D, np.ndarray] | None = (
            Pose2D(cfg.initial_pose_x, cfg.initial_pose_y, cfg.initial_pose_a), cfg.initial_cov())
        self.odom_ref: Pose2D | None = None   # odometry pose at the last filter update
        self.force = False
        self.updates = 0
        self.estimate: Estimate | None = None
        self.map_T_odom: Pose2D | None = None
        self.last_scan: float | None = None   # s, stamp of the last scan used
        # s, the caller's clock when the last scan came (None: use its stamp). A loaded machine delivers
        # scans 1-1.5 s after their stamps: by the stamps alone they would all count as missing
        self.last_heard: float | None = None
        self.scan_times: deque[float] = deque(maxlen=200)     # stamps (s) of recent scans handled
        self.update_times: deque[float] = deque(maxlen=200)   # stamps (s) of recent filter updates
        self.update_ms: deque[float] = deque(maxlen=50)       # wall-clock cost (ms) of recent updates

    @property
    def fit(self) -> float:
        """Weighted mean beam fit (0..1) of the last filter update (nan before the first)."""
        return self.pf.last_fit

    # ------------------------------------------------------------ inputs
    def set_map(self, occ: OccupancyMap) -> None:
        """Use a new map; the filter restarts around the initial (or last) pose. Raises MapError."""
        self.field = LikelihoodField(occ, self.cfg.laser_model())
        if self.pending is None and self.estimate is not None:
            self.pending = (self.estimate.pose, self.cfg.initial_cov())
        self._apply_pending()

    def set_initial_pose(self, pose: Pose2D, cov: np.ndarray) -> str | None:
        """Re-initialise around ``pose`` (cov 3x3); returns why it was refused (off the map), else None."""
        cov = np.asarray(cov, dtype=float)
        if not (all(math.isfinite(v) for v in (pose.x, pose.y, pose.yaw)) and np.isfinite(cov).all()):
            return f"initial pose ({pose.x}, {pose.y}, {pose.yaw}) or its covariance is not finite"
        if self.field is not None and self.field.is_free(pose.x, pose.y) is None:
            return f"initial pose ({pose.x:.2f}, {pose.y:.2f}) is off the map; ignored"
        self.pending = (Pose2D(pose.x, pose.y, wrap_angle(pose.yaw)), cov)
        self._apply_pending()
        return None

    def _apply_pending(self) -> None:
        if self.field is None or self.pending is None:
            return
        pose, cov = self.pending
        self.pending = None
        self.pf.init_gaussian(pose, cov)
        self._after_reinit()

    def global_localization(self) -> bool:
        """Spread the particles over the free space; False without a map."""
        if self.field is None:
            return False
        self.pf.init_uniform(self.field, self.cfg.global_samples)
        self._after_reinit()
        return True

    def _after_reinit(self) -> None:
        self.force = True
        est_pose, cov, _ = self.pf.estimate()
        self.estimate = Estimate(est_pose, cov, self.estimate.stamp if self.estimate else 0.0)

    def request_nomotion_update(self) -> None:
        """Weigh and resample at the next scan even if the robot has not moved."""
        self.force = True

    # ------------------------------------------------------------ updates
    def moved(self, odom: Pose2D) -> bool:
        """Odometry changed enough since the last filter update (amcl's test: |dx|, |dy| or |dyaw|)."""
        ref = self.odom_ref
        return ref is None or (abs(odom.x - ref.x) > self.cfg.update_min_d or
                               abs(odom.y - ref.y) > self.cfg.update_min_d or
                               abs(wrap_angle(odom.yaw - ref.yaw)) > self.cfg.update_min_a)

    def _predict(self, odom: Pose2D) -> None:
        if self.odom_ref is not None:
            self.pf.predict(self.odom_ref, odom, self.noise)
        self.odom_ref = odom

    def update(self, odom: Pose2D, ranges: np.ndarray, angles: np.ndarray, range_min: float, range_max: float,
               laser_pose: Pose2D, t: float) -> bool:
        """One scan at time ``t`` (s) with the base's odometry pose at that time.

        Returns True if the filter ran (moved + weighed); map_T_odom is refreshed
        either way once an estimate exists.  Raises ValueError for a scan without
        a usable beam (the caller reports it).
        """
        if self.field is None:
            raise MapError("no map yet")
        cfg = self.cfg
        rmin = cfg.laser_min_range if cfg.laser_min_range > 0 else range_min
        rmax = cfg.laser_max_range if cfg.laser_max_range > 0 else range_max
        if not (math.isfinite(rmax) and rmax > 0):
            raise ValueError(f"scan range_max must be a finite number > 0 m, got {rmax}")
        ran = False
        self.scan_times.append(t)
        if self.force or self.moved(odom):
            t0 = time.perf_counter()
            endpoints = select_beams(ranges, angles, max(rmin, 0.0), rmax, cfg.laser_max_beams, laser_pose)
            self._predict(odom)
            self.last_scan = t
            if len(endpoints) == 0:   # e.g. the depth camera right at a table: odometry only, the spread grows
                pose, cov, _ = self.pf.estimate()
                self.estimate = Estimate(pose, cov, t)
                # map->odom from the estimate all the same: a robot started facing a wall closer than the
                # camera's minimum range is localized by its initial pose (and seen by the others)
                self.map_T_odom = map_to_odom(pose, odom)
                raise ValueError("scan has no valid beam (all NaN/inf or out of range)")
            through = cfg.laser_through_dist
            before = points_before(endpoints, laser_pose, through) if through > 0 else None
            self.pf.weigh(self.field, endpoints, rmax, before)
            pose, cov, _ = self.pf.estimate()
            self.estimate = Estimate(pose, cov, t)
            self.updates += 1
            if self.updates % cfg.resample_interval == 0:
                self.pf.resample(self.field)
            self.force = False
            ran = True
            self.update_times.append(t)
            self.update_ms.append((time.perf_counter() - t0) * 1e3)
        self.last_scan = t
        if self.estimate is not None and ran:
            self.map_T_odom = map_to_odom(self.estimate.pose, odom)
        return ran

    def predict_only(self, odom: Pose2D, t: float) -> bool:
        """No scan: move the particles by odometry alone (the spread grows); True if they moved."""
        if self.field is None or self.odom_ref is None or not self.moved(odom):
            return False
        self._predict(odom)
        pose, cov, _ = self.pf.estimate()
        self.estimate = Estimate(pose, cov, t)
        self.map_T_odom = map_to_odom(pose, odom)
        return True

    # ------------------------------------------------------------ reporting
    def pose_params(self) -> dict[str, float]:
        """The estimate as amcl saves it on the parameter server (``initial_pose_*``, ``initial_cov_*``)."""
        if self.estimate is None:
            return {}
        p, c = self.estimate.pose, self.estimate.cov
        return {"initial_pose_x": p.x, "initial_pose_y": p.y, "initial_pose_a": p.yaw,
                "initial_cov_xx": float(c[0, 0]), "initial_cov_yy": float(c[1, 1]), "initial_cov_aa": float(c[2, 2])}

    def scan_age(self, t: float) -> float:
        """s since the last scan came at time ``t`` (by ``last_heard`` when the caller sets it, else by the
        scan's stamp); inf before the first."""
        if self.last_scan is None:
            return math.inf
        return t - (self.last_heard if self.last_heard is not None else self.last_scan)

    def diagnostics(self, t: float) -> tuple[int, str, dict[str, float]]:
        """(level, message, values) for /diagnostics at time ``t`` (s)."""
        cfg = self.cfg
        if self.field is None:
            return ERROR, "no usable map yet", {}
        values = {"particles": float(len(self.pf.particles)), "updates": float(self.updates),
                  "mean_beam_fit": self.fit, "w_slow": self.pf.w_slow, "w_fast": self.pf.w_fast,
                  "injected_last_resample": float(self.pf.injected),
                  "estimate_switches": float(self.pf.switches),
                  "heavier_look_alikes_refused": float(self.pf.refused)}
        if self.estimate is not None:
            e = self.estimate
            values.update(x=e.pose.x, y=e.pose.y, yaw=e.pose.yaw, std_xy=e.spread,
                          std_yaw=math.sqrt(max(e.cov[2, 2], 0.0)))
        age = self.scan_age(t)
        values["scan_age"] = age
        if self.last_scan is not None and self.last_heard is not None:
            values["scan_latency"] = self.last_heard - self.last_scan
        values["scans_per_s"] = float(sum(1 for s in self.scan_times if t - 2.0 < s <= t)) / 2.0
        values["updates_per_s"] = float(sum(1 for s in self.update_times if t - 2.0 < s <= t)) / 2.0
        values["update_ms_mean"] = float(sum(self.update_ms) / len(self.update_ms)) if self.update_ms else math.nan
        if age > cfg.scan_timeout:
            return WARN, (f"no scan for {age:.1f} s: publishing the last map->odom, "
                          "the estimate drifts with odometry"), values
        if self.estimate is not None and self.estimate.spread > cfg.spread_warn:
            return WARN, (f"not localized: position spread {self.estimate.spread:.2f} m > {cfg.spread_warn} m "
                          "(give a pose with initialpose or call global_localization)"), values
        if math.isfinite(self.fit) and self.fit < cfg.fit_warn:
            return WARN, (f"estimate may be wrong: mean beam fit {self.fit:.2f} < {cfg.fit_warn} "
                          "(scan does not match the map there)"), values
        return OK, "localized", values
