"""AMCL core, models: motion model moments, likelihood field vs brute force, KLD bound, resampler."""
from __future__ import annotations

import math

import numpy as np
import pytest
from scipy import stats

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import GridInfo, OccupancyMap
from chefbot_navigation.amcl.motion import (
    DiffMotionNoise,
    apply_deltas,
    deltas_stddev,
    odometry_deltas,
    sample_deltas,
    sample_motion,
)
from chefbot_navigation.amcl.resample import clusters, kld_bound, kld_count, low_variance_indices, weighted_mean_cov
from chefbot_navigation.amcl.sensor import LaserModel, LikelihoodField, MapError, points_before, select_beams

NOISE = DiffMotionNoise(0.05, 0.02, 0.03, 0.01)


# ------------------------------------------------------------------ motion model
def test_odometry_deltas_reproduce_the_motion() -> None:
    old, new = Pose2D(1.0, 2.0, 0.3), Pose2D(1.5, 2.4, 1.1)
    rot1, trans, rot2 = odometry_deltas(old, new)
    moved = apply_deltas(np.array([[old.x, old.y, old.yaw]]), np.array([rot1]), np.array([trans]), np.array([rot2]))
    assert moved[0] == pytest.approx([new.x, new.y, new.yaw])


def test_sampled_deltas_have_the_analytic_moments() -> None:
    rot1, trans, rot2 = 0.4, 0.8, -0.3
    rng = np.random.default_rng(1)
    n = 200_000
    r1, t, r2 = sample_deltas(rot1, trans, rot2, NOISE, n, rng)
    want = [math.sqrt(NOISE.alpha1 * rot1 ** 2 + NOISE.alpha2 * trans ** 2),
            math.sqrt(NOISE.alpha3 * trans ** 2 + NOISE.alpha4 * (rot1 ** 2 + rot2 ** 2)),
            math.sqrt(NOISE.alpha1 * rot2 ** 2 + NOISE.alpha2 * trans ** 2)]
    assert deltas_stddev(rot1, trans, rot2, NOISE) == pytest.approx(want)
    for samples, mean, sd in zip((r1, t, r2), (rot1, trans, rot2), want, strict=True):
        se = sd / math.sqrt(n)
        assert abs(samples.mean() - mean) < 5 * se
        assert samples.std() == pytest.approx(sd, rel=0.01)
    # independent components
    assert abs(np.corrcoef(r1, t)[0, 1]) < 0.01 and abs(np.corrcoef(t, r2)[0, 1]) < 0.01


def test_pose_covariance_matches_the_linearised_propagation() -> None:
    old, new = Pose2D(0.0, 0.0, 0.2), Pose2D(0.3, 0.15, 0.5)
    rot1, trans, rot2 = odometry_deltas(old, new)
    start = Pose2D(2.0, -1.0, -0.7)
    rng = np.random.default_rng(2)
    n = 200_000
    p = sample_motion(np.tile([start.x, start.y, start.yaw], (n, 1)), old, new, NOISE, rng)
    h = start.yaw + rot1
    # d(x, y, yaw) / d(rot1, trans, rot2)
    jac = np.array([[-trans * math.sin(h), math.cos(h), 0.0],
                    [trans * math.cos(h), math.sin(h), 0.0],
                    [1.0, 0.0, 1.0]])
    cov = jac @ np.diag(np.square(deltas_stddev(rot1, trans, rot2, NOISE))) @ jac.T
    mean_want = start.compose(old.inverse().compose(new))
    assert p[:, 0].mean() == pytest.approx(mean_want.x, abs=2e-3)
    assert p[:, 1].mean() == pytest.approx(mean_want.y, abs=2e-3)
    assert np.cov(p.T) == pytest.approx(cov, rel=0.05, abs=2e-6)


def test_driving_backwards_is_not_noisy_like_a_half_turn() -> None:
    rot1, trans, rot2 = odometry_deltas(Pose2D(0, 0, 0), Pose2D(-0.3, 0.0, 0.0))
    assert abs(abs(rot1) - math.pi) < 1e-9
    s = deltas_stddev(rot1, trans, rot2, NOISE)
    assert s == pytest.approx(deltas_stddev(0.0, trans, 0.0, NOISE), abs=1e-9)


def test_motion_noise_rejects_negative_alphas() -> None:
    with pytest.raises(ValueError, match="odom_alpha3"):
        DiffMotionNoise(0.1, 0.1, -0.1, 0.1)


# ------------------------------------------------------------------ likelihood field
def random_map(seed: int, h: int = 23, w: int = 31) -> OccupancyMap:
    rng = np.random.default_rng(seed)
    data = np.where(rng.random((h, w)) < 0.08, 100, 0).astype(np.int8)
    data[rng.random((h, w)) < 0.05] = -1
    data[0, 0] = 100
    data[-1, -1] = 0
    return OccupancyMap(GridInfo(0.1, w, h, -1.0, 0.5, 0.0), data)


@pytest.mark.parametrize("seed", range(4))
def test_distance_transform_matches_brute_force(seed: int) -> None:
    occ = random_map(seed)
    occ.data[5:12, 8:20] = 100                           # a solid block: its inside is not a surface
    model = LaserModel(sigma_hit=0.3, likelihood_max_dist=0.7)
    field = LikelihoodField(occ, model)
    occ_mask = occ.data >= 65
    padded = np.pad(occ_mask, 1, constant_values=False)
    all_nb_occ = np.ones_like(occ_mask)
    for dr in (-1, 0, 1):
        for dc in (-1, 0, 1):
            all_nb_occ &= padded[1 + dr:1 + dr + occ_mask.shape[0], 1 + dc:1 + dc + occ_mask.shape[1]]
    rows, cols = np.nonzero(occ_mask & ~all_nb_occ)     # surface cells: brute force
    rr, cc = np.mgrid[0:occ.info.height, 0:occ.info.width]
    d = np.sqrt((rr[..., None] - rows) ** 2 + (cc[..., None] - cols) ** 2).min(axis=-1) * occ.info.resolution
    d = np.minimum(d, model.likelihood_max_dist)
    assert field.distance == pytest.approx(d, abs=1e-9)
    # lookups at cell centres give exp(-d^2 / 2 sigma^2); off the map the capped value
    x, y = occ.info.cell_to_world(rr, cc)
    assert field.fit_at(x, y) == pytest.approx(np.exp(-d ** 2 / (2 * 0.3 ** 2)), abs=1e-6)
    far = math.exp(-0.7 ** 2 / (2 * 0.3 ** 2))
    off = field.fit_at(np.array([-1.01, -5.0, 2.2, 0.0]), np.array([0.6, 0.6, 0.6, 2.81]))
    assert off == pytest.approx([far] * 4, abs=1e-6)


def test_end_points_inside_a_solid_obstacle_do_not_fit() -> None:
    data = np.zeros((40, 40), np.int8)
    data[10:30, 10:30] = 100                              # a 1 m solid block
    field = LikelihoodField(OccupancyMap(GridInfo(0.05, 40, 40), data), LaserModel(sigma_hit=0.2))
    face, inside = field.fit_at(np.array([0.525]), np.array([1.0])), field.fit_at(np.array([0.825]), np.array([1.0]))
    assert face[0] == pytest.approx(1.0) and inside[0] < 0.4


def _wall_view(wall_cells: int) -> tuple[OccupancyMap, np.ndarray, Pose2D]:
    """A wall ``wall_cells`` thick (near face x = 2.5 m, free space beyond it too, as on a raster of a
    building) and a fan of 41 beams from a robot at (1.0, 1.5) facing it, laser 0.1 m ahead."""
    data = np.zeros((60, 80), np.int8)
    data[:, 50:50 + wall_cells] = 100
    laser = Pose2D(0.1, 0.0, 0.0)
    ang = np.linspace(-0.5, 0.5, 41)
    rng = (2.5 - 1.0 - laser.x) / np.cos(ang)
    ends = np.stack([laser.x + rng * np.cos(ang), rng * np.sin(ang)], axis=1).astype(np.float32)
    return OccupancyMap(GridInfo(0.05, 80, 60), data), ends, laser


def _weights_along_x(field: LikelihoodField, ends: np.ndarray, before: np.ndarray | None,
                     shifts: np.ndarray) -> np.ndarray:
    poses = np.stack([1.0 + shifts, np.full_like(shifts, 1.5), np.zeros_like(shifts)], axis=1)
    return field.weights(poses, ends, 8.0, before)[0]


def test_a_pose_pushed_through_a_thick_wall_no_longer_fits() -> None:
    occ, ends, laser = _wall_view(5)                       # 0.25 m: the bistro's walls
    shifts = np.round(np.arange(-0.3, 0.301, 0.01), 2)
    plain = LikelihoodField(occ, LaserModel(sigma_hit=0.1))
    w0 = _weights_along_x(plain, ends, None, shifts)
    truth = w0[np.isclose(shifts, 0.0)][0]
    # without the check the end points 0.2 m into the wall sit on its far face: a second, equal peak
    assert w0[np.isclose(shifts, 0.2)][0] == pytest.approx(truth, rel=0.01)
    checked = LikelihoodField(occ, LaserModel(sigma_hit=0.1, through_dist=0.15))
    w1 = _weights_along_x(checked, ends, points_before(ends, laser, 0.15), shifts)
    assert w1[np.isclose(shifts, 0.0)][0] == pytest.approx(truth)
    assert shifts[np.argmax(w1)] == pytest.approx(0.0)
    assert np.all(w1[shifts >= 0.2] < 1.0 + 0.05 * (truth - 1.0))     # only the random term is left


def test_the_reported_fit_ignores_the_through_check() -> None:
    # the mean fit gates recovery injection: beams zeroed at the true pose (a beam grazing a table
    # against a wall) dropped it below recovery_max_fit and look-alikes were injected (cafe, live)
    occ, ends, laser = _wall_view(5)
    poses = np.array([[1.0, 1.5, 0.0], [1.2, 1.5, 0.0]])
    w0, fit0 = LikelihoodField(occ, LaserModel(sigma_hit=0.1)).weights(poses, ends, 8.0)
    w1, fit1 = LikelihoodField(occ, LaserModel(sigma_hit=0.1, through_dist=0.15)).weights(
        poses, ends, 8.0, points_before(ends, laser, 0.15))
    assert fit1 == pytest.approx(fit0)
    assert w1[1] < w0[1] - 0.5 * (w0[1] - 1.0)


def test_the_through_check_leaves_thin_walls_alone() -> None:
    occ, ends, laser = _wall_view(2)                       # a SLAM map's wall: no interior cell
    shifts = np.round(np.arange(-0.3, 0.301, 0.05), 2)
    plain = _weights_along_x(LikelihoodField(occ, LaserModel(sigma_hit=0.1)), ends, None, shifts)
    checked = _weights_along_x(LikelihoodField(occ, LaserModel(sigma_hit=0.1, through_dist=0.15)), ends,
                               points_before(ends, laser, 0.15), shifts)
    assert checked == pytest.approx(plain)


def test_points_before_lie_on_the_beam_and_stop_at_the_sensor() -> None:
    laser = Pose2D(0.1, 0.2, 0.0)
    ends = np.array([[2.1, 0.2], [0.1, 1.2], [0.15, 0.2]], np.float32)
    got = points_before(ends, laser, 0.15)
    assert got == pytest.approx(np.array([[1.95, 0.2], [0.1, 1.05], [0.1, 0.2]]), abs=1e-6)
    with pytest.raises(ValueError, match="laser_through_dist"):
        LaserModel(through_dist=-0.1)


def test_weights_are_amcl_cubed_sum() -> None:
    occ = random_map(7)
    model = LaserModel(z_hit=0.6, z_rand=0.4, sigma_hit=0.2, likelihood_max_dist=1.0)
    field = LikelihoodField(occ, model)
    p = np.array([[0.3, 1.2, 0.4], [0.8, 1.5, -2.0]])
    ep = np.array([[0.5, 0.1], [1.0, -0.3], [0.2, 0.7]], dtype=np.float32)
    w, fit = field.weights(p, ep, range_max=5.0)
    for i, (x, y, a) in enumerate(p):
        ex = x + math.cos(a) * ep[:, 0] - math.sin(a) * ep[:, 1]
        ey = y + math.sin(a) * ep[:, 0] + math.cos(a) * ep[:, 1]
        f = field.fit_at(ex, ey)
        pz = 0.6 * f + 0.4 / 5.0
        assert w[i] == pytest.approx(1.0 + np.sum(pz ** 3), rel=1e-5)
        assert fit[i] == pytest.approx(f.mean(), rel=1e-5)


def test_unusable_maps_are_named() -> None:
    info = GridInfo(0.05, 10, 10)
    with pytest.raises(MapError, match="no occupied"):
        LikelihoodField(OccupancyMap(info, np.zeros((10, 10), np.int8)), LaserModel())
    with pytest.raises(MapError, match="no free"):
        LikelihoodField(OccupancyMap(info, np.full((10, 10), 100, np.int8)), LaserModel())
    with pytest.raises(MapError, match="empty"):
        LikelihoodField(OccupancyMap(GridInfo(0.05, 0, 0), np.zeros((0, 0), np.int8)), LaserModel())


def test_select_beams_skips_invalid_ranges_and_uses_the_laser_pose() -> None:
    ranges = np.array([np.nan, 1.0, np.inf, -np.inf, 0.2, 2.0, 9.0, 3.0])
    angles = np.linspace(-0.4, 0.4, len(ranges))
    laser = Pose2D(0.1, -0.05, math.pi / 2)
    ep = select_beams(ranges, angles, 0.45, 8.0, 60, laser)
    keep = [1, 5, 7]
    want = np.stack([0.1 + ranges[keep] * np.cos(angles[keep] + math.pi / 2),
                     -0.05 + ranges[keep] * np.sin(angles[keep] + math.pi / 2)], axis=1)
    assert ep == pytest.approx(want, abs=1e-6)
    assert len(select_beams(np.full(5, np.nan), angles[:5], 0.45, 8.0, 60, laser)) == 0
    many = select_beams(np.full(640, 2.0), np.linspace(-3, 3, 640), 0.1, 8.0, 60, Pose2D())
    assert len(many) == 60


# ------------------------------------------------------------------ KLD bound and count
def test_kld_bound_is_the_wilson_hilferty_chi_square_quantile() -> None:
    err, delta = 0.05, 0.01
    z = stats.norm.ppf(1 - delta)
    for k in (5, 20, 100, 1000):
        exact = stats.chi2.ppf(1 - delta, k - 1) / (2 * err)
        assert float(kld_bound(k, err, z)) == pytest.approx(exact, rel=0.02)
    assert float(kld_bound(1, err, z)) == 0.0    # one bin: converged, min_particles
    b = kld_bound(np.arange(2, 200), err, 0.99)
    assert np.all(np.diff(b) >= 0)


def test_kld_count_adapts_between_the_limits() -> None:
    rng = np.random.default_rng(3)
    tight = np.column_stack([rng.normal(1.2, 0.01, 3000), rng.normal(1.2, 0.01, 3000), rng.normal(0.05, 0.01, 3000)])
    assert kld_count(tight, 0.05, 0.99, 500, 2000) == 500
    wide = np.column_stack([rng.uniform(-20, 20, 3000), rng.uniform(-20, 20, 3000), rng.uniform(-3, 3, 3000)])
    assert kld_count(wide, 0.05, 0.99, 500, 2000) == 2000
    mid = np.column_stack([rng.normal(0, 0.3, 3000), rng.normal(0, 0.3, 3000), rng.normal(0, 0.1, 3000)])
    n = kld_count(mid, 0.05, 0.99, 10, 3000)
    assert 10 < n < 3000


# ------------------------------------------------------------------ resampler
def test_low_variance_gives_each_particle_floor_or_ceil_of_its_share() -> None:
    rng = np.random.default_rng(4)
    w = rng.random(50) ** 3
    for seed in range(20):
        idx = low_variance_indices(w, 400, np.random.default_rng(seed))
        counts = np.bincount(idx, minlength=50)
        share = 400 * w / w.sum()
        assert np.all(counts >= np.floor(share) - 1e-9) and np.all(counts <= np.ceil(share) + 1e-9)


def test_low_variance_is_unbiased() -> None:
    w = np.array([0.1, 0.0, 0.6, 0.3])
    counts = sum(np.bincount(low_variance_indices(w, 7, np.random.default_rng(s)), minlength=4)
                 for s in range(4000))
    assert counts / (7 * 4000) == pytest.approx(w, abs=0.005)
    assert counts[1] == 0


def test_low_variance_rejects_zero_weights() -> None:
    with pytest.raises(ValueError, match="positive finite sum"):
        low_variance_indices(np.zeros(5), 5, np.random.default_rng(0))


def test_clusters_split_hypotheses_and_join_across_the_yaw_seam() -> None:
    rng = np.random.default_rng(5)
    a = np.column_stack([rng.normal(1, 0.05, 300), rng.normal(1, 0.05, 300), rng.normal(math.pi - 0.01, 0.03, 300)])
    a[:, 2] = np.mod(a[:, 2] + math.pi, 2 * math.pi) - math.pi      # straddles +-pi
    b = np.column_stack([rng.normal(5, 0.05, 100), rng.normal(-2, 0.05, 100), rng.normal(0.5, 0.03, 100)])
    cl = clusters(np.vstack([a, b]), np.ones(400))
    assert len(cl) == 2
    assert cl[0].weight == pytest.approx(0.75) and cl[0].count == 300
    assert cl[0].mean[0] == pytest.approx(1.0, abs=0.02)
    assert abs(math.remainder(cl[0].mean[2] - (math.pi - 0.01), 2 * math.pi)) < 0.01
    assert cl[1].mean[:2] == pytest.approx((5.0, -2.0), abs=0.02)


def test_weighted_mean_cov_of_a_gaussian() -> None:
    rng = np.random.default_rng(6)
    cov = np.array([[0.04, 0.01, 0.0], [0.01, 0.09, 0.0], [0.0, 0.0, 0.01]])
    p = rng.multivariate_normal([1.0, 2.0, 3.1], cov, 100_000)
    p[:, 2] = np.mod(p[:, 2] + math.pi, 2 * math.pi) - math.pi
    mean, c = weighted_mean_cov(p, np.ones(len(p)))
    assert mean[:2] == pytest.approx([1.0, 2.0], abs=0.005)
    assert abs(math.remainder(mean[2] - 3.1, 2 * math.pi)) < 0.005
    assert c == pytest.approx(cov, abs=0.002)
