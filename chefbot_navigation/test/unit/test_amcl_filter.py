"""AMCL core, whole filter on synthetic scenes: tracking, global localization, kidnap, bad inputs,
map->odom composition.  Statistical outcomes use fixed seeds; bounds are loose (figures: make bench)."""
from __future__ import annotations

import math

import numpy as np
import pytest
from amcl_scenes import cast, drifting_odometry, lawnmower, room_map, symmetric_room

from chefbot_common.geometry import Pose2D, wrap_angle
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.amcl.filter import TRACKED_INJECT_MAX, FilterConfig, ParticleFilter
from chefbot_navigation.amcl.localizer import OK, WARN, Amcl, AmclConfig
from chefbot_navigation.amcl.motion import DiffMotionNoise
from chefbot_navigation.amcl.sensor import LaserModel, LikelihoodField, MapError, select_beams

CAMERA = np.linspace(-0.506, 0.506, 160)        # the depth camera's ~58 degree band
LIDAR = np.linspace(-math.pi, math.pi, 360, endpoint=False)
LASER = Pose2D(0.1, 0.0, 0.0)                   # scan frame in the base frame
ROOM = room_map()


def scan_from(truth: Pose2D, angles: np.ndarray, rng: np.random.Generator) -> np.ndarray:
    r = cast(ROOM, truth.compose(LASER), angles, 8.0)
    r = r + rng.normal(0.0, 0.01, len(r))
    r[r < 0.45] = np.nan                         # too close for the depth camera
    return r


def run(amcl: Amcl, truth: list[Pose2D], odom: list[Pose2D], angles: np.ndarray, seed: int = 0,
        t0: float = 0.0) -> list[tuple[float, float]]:
    """Feed every pose as one scan at 10 Hz; (position error m, yaw error rad) after each."""
    rng = np.random.default_rng(seed)
    errors = []
    for k, (tr, od) in enumerate(zip(truth, odom, strict=True)):
        r = scan_from(tr, angles, rng)
        try:
            amcl.update(od, r, angles, 0.45, 8.0, LASER, t0 + 0.1 * k)
        except ValueError:
            pass                                  # a scan without valid beams: odometry only
        est = amcl.map_T_odom.compose(od)
        errors.append((math.hypot(est.x - tr.x, est.y - tr.y), abs(wrap_angle(est.yaw - tr.yaw))))
    return errors


def config(**kw) -> AmclConfig:
    """amcl's laser settings (param/amcl.yaml), odometry noise of a decent wheel odometry."""
    alphas = {f"odom_alpha{i}": 0.02 for i in range(1, 5)}
    return AmclConfig(**{"seed": 1, **alphas, **kw})


def test_tracks_a_route_with_drifting_odometry_through_the_camera() -> None:
    truth = lawnmower(ROOM)
    odom = drifting_odometry(truth, seed=2)
    start = truth[0]
    amcl = Amcl(config(initial_pose_x=start.x + 0.1, initial_pose_y=start.y - 0.1, initial_pose_a=start.yaw + 0.05,
                       initial_cov_xx=0.02, initial_cov_yy=0.02, initial_cov_aa=0.01))
    amcl.set_map(ROOM)
    errors = np.array(run(amcl, truth, odom, CAMERA))
    settled = errors[20:]
    rms = np.sqrt((settled ** 2).mean(axis=0))
    # odometry alone ends far off: the filter is doing the work
    dead = truth[0].compose(odom[0].inverse().compose(odom[-1]))
    assert math.hypot(dead.x - truth[-1].x, dead.y - truth[-1].y) > 0.5
    assert rms[0] < 0.12 and rms[1] < 0.06, rms
    assert settled[:, 0].max() < 0.4
    assert amcl.updates > 30


def test_map_to_odom_composes_estimate_and_odometry() -> None:
    truth = lawnmower(ROOM)[:40]
    odom = drifting_odometry(truth, seed=3)
    amcl = Amcl(config(initial_pose_x=truth[0].x, initial_pose_y=truth[0].y, initial_pose_a=truth[0].yaw))
    amcl.set_map(ROOM)
    run(amcl, truth, odom, CAMERA)
    # after an update: map->odom = map->base * (odom->base)^-1 at that scan
    rng = np.random.default_rng(0)
    amcl.request_nomotion_update()
    assert amcl.update(odom[-1], scan_from(truth[-1], CAMERA, rng), CAMERA, 0.45, 8.0, LASER, 100.0)
    back = amcl.map_T_odom.compose(odom[-1])
    e = amcl.estimate.pose
    assert (back.x, back.y) == pytest.approx((e.x, e.y), abs=1e-9)
    assert wrap_angle(back.yaw - e.yaw) == pytest.approx(0.0, abs=1e-9)


def spin_in_place(at: Pose2D, seconds: float, rate: float = 0.6) -> list[Pose2D]:
    return [Pose2D(at.x, at.y, wrap_angle(at.yaw + rate * 0.1 * k)) for k in range(int(seconds * 10))]


@pytest.mark.parametrize(("angles", "seconds"), [(LIDAR, 6.0), (CAMERA, 30.0)], ids=["lidar360", "camera58"])
def test_global_localization_while_rotating(angles: np.ndarray, seconds: float) -> None:
    at = Pose2D(2.6, 2.9, 0.3)
    truth = spin_in_place(at, seconds)
    odom = drifting_odometry(truth, seed=4)
    amcl = Amcl(config(update_min_a=0.1))
    amcl.set_map(ROOM)
    assert amcl.global_localization()
    assert amcl.estimate.spread > 1.0
    errors = run(amcl, truth, odom, angles)
    assert errors[-1][0] < 0.25 and errors[-1][1] < 0.25, errors[-1]
    assert amcl.estimate.spread < 0.25


def test_kidnapped_robot_is_recovered_with_the_alphas_on() -> None:
    truth = lawnmower(ROOM)
    odom = drifting_odometry(truth, seed=5)
    amcl = Amcl(config(initial_pose_x=truth[0].x, initial_pose_y=truth[0].y, initial_pose_a=truth[0].yaw))
    amcl.set_map(ROOM)
    half = len(truth) // 2
    run(amcl, truth[:half], odom[:half], LIDAR)
    assert amcl.pf.w_diff == 0.0
    # kidnap: carried 3 m away, odometry does not notice
    shift = Pose2D(3.0, 0.0, 0.0) if truth[half].x < 4.0 else Pose2D(-3.0, 0.0, 0.0)
    moved = [Pose2D(p.x + shift.x, p.y + shift.y, p.yaw) for p in spin_in_place(truth[half], 40.0)]
    errors = run(amcl, moved, drifting_odometry(moved, seed=6), LIDAR, t0=100.0)
    assert errors[5][0] > 1.0                 # still lost just after the kidnap
    assert errors[-1][0] < 0.25 and errors[-1][1] < 0.25, errors[-1]


def _two_clusters(pf: ParticleFilter, w_tracked: float) -> None:
    """Half the particles at (2, 2, 0), half at the look-alike (6, 3, pi); weights w_tracked : 1 - w_tracked."""
    rng = np.random.default_rng(1)
    n = len(pf.particles) // 2
    a = np.column_stack([2.0 + 0.02 * rng.standard_normal(n), 2.0 + 0.02 * rng.standard_normal(n), np.zeros(n)])
    b = np.column_stack([6.0 + 0.02 * rng.standard_normal(n), 3.0 + 0.02 * rng.standard_normal(n),
                         np.full(n, math.pi)])
    pf.particles = np.concatenate([a, b])
    pf.weights = np.concatenate([np.full(n, w_tracked / n), np.full(n, (1.0 - w_tracked) / n)])


def test_covariance_is_the_estimates_cluster_while_it_holds_the_majority() -> None:
    """Recovery injects a few % of particles metres away on a normal route: the whole set's spread
    was then 0.5-1 m ("not localized" while tracking within 3 cm).  The estimate's cluster's
    covariance is reported while that cluster holds most of the weight; without a majority (several
    hypotheses) the whole set's."""
    pf = ParticleFilter(FilterConfig(min_particles=10, max_particles=400), np.random.default_rng(0))
    pf.tracked = Pose2D(2.0, 2.0, 0.0)
    _two_clusters(pf, 0.9)                      # 10 % injected 4 m away
    _, cov, cl = pf.estimate()
    assert cl[0].weight == pytest.approx(0.9)
    assert math.sqrt(cov[0, 0] + cov[1, 1]) < 0.1
    _two_clusters(pf, 0.45)                     # two hypotheses, neither a majority
    _, cov, _ = pf.estimate()
    assert math.sqrt(cov[0, 0] + cov[1, 1]) > 1.0


def test_estimate_stays_with_the_tracked_cluster_until_another_clearly_outweighs_it() -> None:
    """A look-alike cluster (recovery injection) slightly heavier for an update must not move the
    estimate; one switch_ratio times heavier does (a real kidnap), and switch_ratio 1 is amcl's rule."""
    pf = ParticleFilter(FilterConfig(min_particles=10, max_particles=400), np.random.default_rng(0))
    pf.init_gaussian(Pose2D(2.0, 2.0, 0.0), np.diag([1e-4, 1e-4, 1e-4]))
    first, _, _ = pf.estimate()
    assert math.hypot(first.x - 2.0, first.y - 2.0) < 0.05
    # odometry moves the tracked pose along: 0.5 m ahead is still the same cluster after the step
    pf.predict(Pose2D(0.0, 0.0, 0.0), Pose2D(0.5, 0.0, 0.0), DiffMotionNoise(0.0, 0.0, 0.0, 0.0))
    assert pf.tracked is not None and abs(pf.tracked.x - 2.5) < 0.05
    pf.tracked = Pose2D(2.0, 2.0, 0.0)
    _two_clusters(pf, 0.3)                      # the look-alike 0.7 : 0.3 (< 3x)
    est, _, cl = pf.estimate()
    assert cl[0].mean[0] > 5.0                  # the look-alike is the heaviest ...
    assert math.hypot(est.x - 2.0, est.y - 2.0) < 0.05 and pf.switches == 0   # ... yet the estimate stays
    _two_clusters(pf, 0.2)                      # 0.8 : 0.2 = 4x: the tracked one is dying out
    est, _, _ = pf.estimate()
    assert math.hypot(est.x - 6.0, est.y - 3.0) < 0.05 and pf.switches == 1
    amcl_rule = ParticleFilter(FilterConfig(min_particles=10, max_particles=400, switch_ratio=1.0),
                               np.random.default_rng(0))
    amcl_rule.tracked = Pose2D(2.0, 2.0, 0.0)
    _two_clusters(amcl_rule, 0.45)
    est, _, _ = amcl_rule.estimate()
    assert est.x > 5.0                          # amcl: always the heaviest
    with pytest.raises(ValueError, match="estimate_switch_ratio"):
        FilterConfig(switch_ratio=0.5)
    # a re-initialisation forgets the tracked pose
    pf.init_gaussian(Pose2D(1.0, 1.0, 0.0), np.diag([1e-4, 1e-4, 1e-4]))
    assert pf.tracked is None


def test_recent_scans_are_carried_by_odometry_into_the_current_base_frame() -> None:
    """The recovery pool is scored on earlier scans too: their end points must follow the odometry."""
    pf = ParticleFilter(FilterConfig(min_particles=10, max_particles=10, inject_scans=2, inject_beams=4),
                        np.random.default_rng(0))
    field = LikelihoodField(ROOM, LaserModel())
    pf.init_gaussian(Pose2D(2.0, 2.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    world = [(3.0, 2.0), (1.0, 4.5)]          # two fixed points, in the odometry frame
    a, b, c = Pose2D(1.0, 1.0, 0.3), Pose2D(1.4, 1.2, 1.1), Pose2D(1.5, 1.0, -2.0)

    def seen_from(p: Pose2D) -> np.ndarray:
        return np.array([[q.x, q.y] for q in (p.inverse().compose(Pose2D(x, y, 0.0)) for x, y in world)],
                        dtype=np.float32)

    quiet = DiffMotionNoise(0.0, 0.0, 0.0, 0.0)
    pf.weigh(field, seen_from(a), 8.0)
    pf.predict(a, b, quiet)
    np.testing.assert_allclose(pf.recent_endpoints(), seen_from(b), atol=1e-5)
    pf.weigh(field, seen_from(b)[:1], 8.0)
    pf.predict(b, c, quiet)
    pf.weigh(field, seen_from(c)[1:], 8.0)   # a third scan: the first falls out (inject_scans 2)
    np.testing.assert_allclose(pf.recent_endpoints(), seen_from(c), atol=1e-5)
    pf.init_gaussian(Pose2D(2.0, 2.0, 0.0), np.diag([0.01, 0.01, 0.01]))
    assert len(pf.recent_endpoints()) == 0    # a new initial pose forgets them


def test_kidnap_through_the_camera_is_recovered_while_turning() -> None:
    """The narrow camera sees one wall at a time: the pool is scored on the last turn's scans."""
    start = Pose2D(2.6, 2.9, 0.0)
    amcl = Amcl(config(initial_pose_x=start.x, initial_pose_y=start.y, initial_pose_a=start.yaw,
                       initial_cov_xx=0.01, initial_cov_yy=0.01, initial_cov_aa=0.01, update_min_a=0.05))
    amcl.set_map(ROOM)
    before = spin_in_place(start, 5.0)
    run(amcl, before, drifting_odometry(before, seed=8), CAMERA)
    moved = spin_in_place(Pose2D(start.x + 2.5, start.y - 0.8, before[-1].yaw), 30.0)
    errors = run(amcl, moved, drifting_odometry(moved, seed=9), CAMERA, t0=100.0)
    assert errors[3][0] > 1.0                 # lost just after the kidnap
    ok = [e[0] < 0.25 and e[1] < 0.25 for e in errors]
    assert all(ok[-50:]), errors[-50:]        # localized for the last 5 s


def test_without_recovery_the_kidnap_is_reported_not_hidden() -> None:
    truth = spin_in_place(Pose2D(2.6, 2.9, 0.0), 8.0)
    amcl = Amcl(config(recovery_alpha_slow=0.0, recovery_alpha_fast=0.0,
                       initial_pose_x=6.0, initial_pose_y=4.2, initial_pose_a=-2.0,
                       initial_cov_xx=0.01, initial_cov_yy=0.01, initial_cov_aa=0.01))
    amcl.set_map(ROOM)
    run(amcl, truth, drifting_odometry(truth, seed=7), CAMERA)
    level, message, values = amcl.diagnostics(8.0)
    assert level == WARN and "fit" in message, (message, values)
    assert values["mean_beam_fit"] < 0.5


def test_initial_pose_reinitialises_and_off_map_is_refused() -> None:
    amcl = Amcl(config())
    amcl.set_map(ROOM)
    assert amcl.set_initial_pose(Pose2D(3.0, 2.5, 1.0), np.diag([0.01, 0.01, 0.001])) is None
    assert amcl.estimate.pose.x == pytest.approx(3.0, abs=0.02) and amcl.estimate.spread < 0.15
    err = amcl.set_initial_pose(Pose2D(30.0, 2.5, 1.0), np.eye(3) * 0.01)
    assert err is not None and "off the map" in err
    assert amcl.estimate.pose.x == pytest.approx(3.0, abs=0.02)      # unchanged
    assert "not finite" in amcl.set_initial_pose(Pose2D(math.nan, 0, 0), np.eye(3))


def test_a_robot_started_facing_a_wall_too_close_to_see_is_localized_by_its_initial_pose() -> None:
    """Every beam below the camera's minimum range: no weighing, but map->odom from the initial pose
    (without it the robot's tf tree stays broken: move_base and the fleet do not know where it is)."""
    amcl = Amcl(config())
    amcl.set_map(ROOM)
    amcl.set_initial_pose(Pose2D(3.0, 2.5, 1.0), np.diag([0.01, 0.01, 0.001]))
    odom = Pose2D(0.4, -0.2, 0.3)
    with pytest.raises(ValueError, match="no valid beam"):
        amcl.update(odom, np.full(160, 0.3), CAMERA, 0.45, 8.0, LASER, 1.0)
    assert amcl.map_T_odom is not None
    here = amcl.map_T_odom.compose(odom)
    assert math.hypot(here.x - 3.0, here.y - 2.5) < 0.05 and abs(here.yaw - 1.0) < 0.02


def test_bad_scans_and_maps_raise_clear_errors() -> None:
    amcl = Amcl(config())
    with pytest.raises(MapError, match="no map"):
        amcl.update(Pose2D(), np.ones(5), np.zeros(5), 0.1, 8.0, LASER, 0.0)
    assert amcl.diagnostics(0.0)[0] == 2
    with pytest.raises(MapError, match="no occupied"):
        amcl.set_map(OccupancyMap(GridInfo(0.05, 20, 20), np.zeros((20, 20), np.int8)))
    amcl.set_map(ROOM)
    with pytest.raises(ValueError, match="no valid beam"):
        amcl.update(Pose2D(), np.full(160, np.nan), CAMERA, 0.45, 8.0, LASER, 0.0)
    with pytest.raises(ValueError, match="range_max"):
        amcl.update(Pose2D(), np.ones(160), CAMERA, 0.45, math.inf, LASER, 0.0)


def test_no_scans_the_spread_grows_with_driving_and_diagnostics_say_so() -> None:
    truth = lawnmower(ROOM)[:60]
    odom = drifting_odometry(truth, seed=8)
    amcl = Amcl(config(initial_pose_x=truth[0].x, initial_pose_y=truth[0].y, initial_pose_a=truth[0].yaw))
    amcl.set_map(ROOM)
    run(amcl, truth[:20], odom[:20], CAMERA)
    before = amcl.estimate.spread
    for k, od in enumerate(odom[20:]):
        amcl.predict_only(od, 2.0 + 0.1 * k)
    assert amcl.estimate.spread > before
    level, message, _ = amcl.diagnostics(10.0)
    assert level == WARN and "no scan" in message
    assert amcl.diagnostics(amcl.last_scan)[0] in (OK, WARN)


def test_late_scans_are_not_missing_scans() -> None:
    """On a loaded machine scans come 1-1.5 s after their stamps.  Counted by the stamps they were all
    missing: diagnostics said "no scan" and the node moved the particles by odometry alone between
    them.  The age is taken from when the last scan came (last_heard, set by the node) when known."""
    amcl = Amcl(config(initial_pose_x=2.0, initial_pose_y=3.0))
    amcl.set_map(ROOM)
    truth = Pose2D(2.0, 3.0, 0.0)
    ranges = scan_from(truth, CAMERA, np.random.default_rng(0))
    amcl.last_heard = 11.4                        # came at 11.4 s, stamped 10.0 s
    amcl.update(truth, ranges, CAMERA, 0.45, 8.0, LASER, 10.0)
    assert amcl.scan_age(11.9) == pytest.approx(0.5)
    level, message, values = amcl.diagnostics(11.9)
    assert "no scan" not in message and values["scan_latency"] == pytest.approx(1.4)
    level, message, _ = amcl.diagnostics(12.6)    # and none since: 1.2 s > scan_timeout 1 s
    assert level == WARN and message.startswith("no scan for 1.2 s")
    by_stamp = Amcl(config(initial_pose_x=2.0, initial_pose_y=3.0))
    by_stamp.set_map(ROOM)
    by_stamp.update(truth, ranges, CAMERA, 0.45, 8.0, LASER, 10.0)
    assert by_stamp.scan_age(11.9) == pytest.approx(1.9)    # no arrival time given: the stamp


def test_config_rejects_bad_values_by_name() -> None:
    with pytest.raises(ValueError, match="min_particles"):
        AmclConfig(min_particles=3000)
    with pytest.raises(ValueError, match="laser_model_type"):
        AmclConfig(laser_model_type="beam")
    with pytest.raises(ValueError, match="odom_alpha2"):
        AmclConfig(odom_alpha2=-1.0)
    with pytest.raises(ValueError, match="recovery_alpha_fast"):
        AmclConfig(recovery_alpha_slow=0.2, recovery_alpha_fast=0.1)


def test_shipped_param_file_is_complete_and_valid() -> None:
    """param/amcl.yaml: every key is a parameter the node reads, and the values pass validation."""
    import dataclasses
    from pathlib import Path

    import yaml

    params = yaml.safe_load((Path(__file__).resolve().parents[2] / "param" / "amcl.yaml").read_text())
    fields = {f.name for f in dataclasses.fields(AmclConfig)}
    assert set(params) <= fields, set(params) - fields
    assert set(params) == fields, f"not pinned in amcl.yaml: {fields - set(params)}"
    cfg = AmclConfig(**params)
    assert cfg.laser_max_beams == 60 and cfg.min_particles == 500 and cfg.max_particles == 2000


def test_recovery_waits_for_a_poor_fit() -> None:
    """w_fast below w_slow injects (amcl) only while the set's mean beam fit is below max_fit: a view
    that fits worse than the average but well (a long corridor, 0.75) injects nothing, a kidnap's
    poor fit does; max_fit 1 is amcl's rule (the alphas alone)."""
    gated = ParticleFilter(FilterConfig(min_particles=10, max_particles=100, max_fit=0.7), np.random.default_rng(0))
    amcl_rule = ParticleFilter(FilterConfig(min_particles=10, max_particles=100), np.random.default_rng(0))
    for pf in (gated, amcl_rule):
        pf.w_slow, pf.w_fast = 1.0, 0.78
        pf.last_fit = 0.75
    assert gated.w_diff == 0.0
    assert amcl_rule.w_diff == pytest.approx(0.22)
    gated.last_fit = 0.3
    assert gated.w_diff == pytest.approx(0.22)
    with pytest.raises(ValueError, match="recovery_max_fit"):
        FilterConfig(max_fit=0.0)


def test_a_fit_that_never_was_good_still_injects() -> None:
    """After global localization the set can settle on a look-alike that fits poorly (0.4-0.6) while
    w_fast never drops below w_slow (the fit was never better): amcl's rule injects nothing and the
    true pose, never sampled, is lost.  With poor_fit_rate, no particle fitting well (the best one
    below max_fit) injects at least that fraction; one good particle stops it, and 0 is amcl's rule."""
    def pf(rate: float) -> ParticleFilter:
        f = ParticleFilter(FilterConfig(min_particles=10, max_particles=100, max_fit=0.7, poor_fit_rate=rate),
                           np.random.default_rng(0))
        f.w_slow = f.w_fast = 0.05          # steady: nothing dropped
        f.last_fit, f.best_fit = 0.5, 0.6
        return f

    assert pf(0.0).w_diff == 0.0
    assert pf(0.1).w_diff == pytest.approx(0.1)
    dropped = pf(0.1)
    dropped.w_fast = 0.02                   # a drop (kidnap) injects by the averages' rule, more
    assert dropped.w_diff == pytest.approx(0.6)
    found = pf(0.1)
    found.best_fit = 0.75                   # a particle explains the scans: the set's poor mean (the injected
    assert found.w_diff == 0.0              # ones among it) does not keep injecting
    fresh = ParticleFilter(FilterConfig(max_fit=0.7, poor_fit_rate=0.1), np.random.default_rng(0))
    assert fresh.w_diff == 0.0              # nothing weighed yet
    with pytest.raises(ValueError, match="recovery_poor_fit_rate"):
        FilterConfig(poor_fit_rate=1.0)


def test_no_injection_while_the_estimates_own_particles_fit_the_scan() -> None:
    """The set's mean fit counts the injected particles, most of which fit poorly: with scans late (a
    loaded machine) that mean stayed low, injected more, and a look-alike took the estimate from a
    cluster that fitted the scans.  While the particles around the estimate fit well at most
    TRACKED_INJECT_MAX is injected; after a kidnap they fit badly and the averages' rule injects as before."""
    truth = Pose2D(2.5, 3.0, 0.3)
    field = LikelihoodField(ROOM, LaserModel(sigma_hit=0.1))
    ranges = scan_from(truth, CAMERA, np.random.default_rng(0))
    endpoints = select_beams(ranges, CAMERA, 0.45, 8.0, 60, LASER)

    def weighed(tracked: Pose2D) -> ParticleFilter:
        pf = ParticleFilter(FilterConfig(min_particles=10, max_particles=400, max_fit=0.7),
                            np.random.default_rng(0))
        pf.init_gaussian(truth, np.diag([1e-4, 1e-4, 1e-4]))
        pf.particles[200:] = field.sample_free(200, np.random.default_rng(1))   # half injected guesses
        pf.tracked = tracked
        pf.weigh(field, endpoints, 8.0)
        pf.w_slow, pf.w_fast, pf.last_fit = 1.0, 0.4, 0.45   # the averages and the set's mean say: inject
        return pf

    on_track = weighed(truth)
    assert on_track.tracked_fit > 0.7, on_track.tracked_fit
    assert on_track.w_diff == pytest.approx(TRACKED_INJECT_MAX)   # capped: the set is not replaced
    assert TRACKED_INJECT_MAX < 0.5
    kidnapped = weighed(Pose2D(6.0, 2.0, 2.0))      # the estimate is elsewhere: its particles fit nothing
    assert not kidnapped.tracked_fit >= 0.7         # nan (no particle there) or a poor fit
    assert kidnapped.w_diff == pytest.approx(0.6)


def test_global_localization_leaves_a_poorly_fitting_look_alike() -> None:
    """The whole set on a wrong place that fits the scans poorly, the averages steady: with
    poor_fit_rate the scored injection finds the true pose within a few seconds of turning, and
    (estimate_min_gain, as shipped) the estimate stays there once it is found."""
    at = Pose2D(2.6, 2.9, 0.3)
    truth = spin_in_place(at, 8.0)
    odom = drifting_odometry(truth, seed=7)
    wrong = Pose2D(5.6, 2.0, 0.3)

    def final_error(rate: float) -> float:
        amcl = Amcl(config(update_min_a=0.1, recovery_max_fit=0.7, recovery_poor_fit_rate=rate, estimate_min_gain=0.1,
                           initial_pose_x=wrong.x, initial_pose_y=wrong.y, initial_pose_a=wrong.yaw,
                           initial_cov_xx=0.0025, initial_cov_yy=0.0025, initial_cov_aa=0.0025))
        amcl.set_map(ROOM)
        return run(amcl, truth, odom, LIDAR)[-1][0]

    assert final_error(0.1) < 0.25
    assert final_error(0.0) > 1.0


def test_estimate_does_not_follow_a_heavier_look_alike_that_fits_the_scans_no_better() -> None:
    """In a room that looks the same turned 180 deg, recovery injection seeds the look-alike place,
    and resampling can make it the heavier cluster although it explains the scans no better (the
    hotel SLAM workflow's failure: the estimate jumped 6.1 m and turned 180 deg).  With
    estimate_min_gain the estimate stays unless the other cluster's best pose also fits the recent
    scans that much better than the tracked cluster's: a kidnap (the tracked cluster somewhere
    else) still moves it; 0 is the weight rule alone."""
    occ = symmetric_room()
    field = LikelihoodField(occ, LaserModel(sigma_hit=0.1))
    truth = Pose2D(2.5, 2.0, 0.3)
    mirror = Pose2D(8.0 - truth.x, 6.0 - truth.y, wrap_angle(truth.yaw + math.pi))
    pts = select_beams(cast(occ, truth.compose(LASER), LIDAR, 8.0), LIDAR, 0.1, 8.0, 180, LASER)
    fits = field.weights(np.array([[truth.x, truth.y, truth.yaw], [mirror.x, mirror.y, mirror.yaw]]), pts, 8.0)[1]
    assert abs(fits[0] - fits[1]) < 0.02 and fits.min() > 0.9        # a true look-alike

    def estimate(min_gain: float, tracked: Pose2D, heavier: Pose2D) -> Pose2D:
        """The estimate when ``heavier``'s cluster holds 4x the weight of ``tracked``'s; checks the counts."""
        pf = ParticleFilter(FilterConfig(min_particles=10, max_particles=400, min_gain=min_gain),
                            np.random.default_rng(3))
        pf.init_gaussian(truth, np.diag([1e-4, 1e-4, 1e-4]))
        pf.weigh(field, pts, 8.0)                                     # the recent scan
        rng = np.random.default_rng(4)
        pf.particles = np.concatenate([np.array([[p.x, p.y, p.yaw]]) + 0.02 * rng.standard_normal((200, 3))
                                       for p in (tracked, heavier)])
        pf.weights = np.concatenate([np.full(200, 0.2 / 200), np.full(200, 0.8 / 200)])
        pf.tracked = tracked
        est = pf.estimate()[0]
        moved = est.distance(tracked) > 0.5
        assert (pf.switches, pf.refused) == ((1, 0) if moved else (0, 1))
        return est

    assert estimate(0.1, truth, mirror).distance(truth) < 0.05       # heavier, but no better: stays
    assert estimate(0.0, truth, mirror).distance(mirror) < 0.05      # the weight rule alone: jumps
    lost = Pose2D(6.0, 1.5, 2.0)                                      # kidnapped: the tracked place fits badly
    assert estimate(0.1, lost, truth).distance(truth) < 0.05
    with pytest.raises(ValueError, match="estimate_min_gain"):
        FilterConfig(min_gain=1.0)
