"""Branch-and-bound coarse search of the scan matcher: the same result as the exhaustive search (no master)."""
from __future__ import annotations

import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_navigation.slam import scan_matcher
from chefbot_navigation.slam.scan_matcher import (
    LikelihoodField,
    MatchResult,
    SearchWindow,
    match,
    match_exhaustive,
)


@pytest.fixture(autouse=True)
def _always_branch_and_bound(monkeypatch):
    """match() falls back to the exhaustive search for small windows: force the branch and bound."""
    monkeypatch.setattr(scan_matcher, "EXHAUSTIVE_BELOW", 0)


def assert_same(a: MatchResult, b: MatchResult) -> None:
    assert math.isclose(a.pose.x, b.pose.x, abs_tol=1e-9)
    assert math.isclose(a.pose.y, b.pose.y, abs_tol=1e-9)
    assert math.isclose(a.pose.yaw, b.pose.yaw, abs_tol=1e-9)
    assert a.score == pytest.approx(b.score, abs=1e-9)
    assert a.beams == b.beams
    assert a.spread == pytest.approx(b.spread, abs=1e-9)
    assert a.on_border == b.on_border


def coarse_pair(field: LikelihoodField, pts: np.ndarray, prior: Pose2D, window: SearchWindow,
                prior_sigma, beams_per_dof: float) -> tuple[tuple, tuple]:
    """(angle index, row offset index, column offset index, spread) of both coarse searches."""
    co = scan_matcher._coarse(field, pts, prior, window)
    rank = scan_matcher._Ranking(field.res, co.dths, window, len(pts), prior_sigma, beams_per_dof)
    return scan_matcher._search_bnb(field, co, rank), scan_matcher._search_exhaustive(field, co, rank)


def random_field(rng: np.random.Generator) -> LikelihoodField:
    res = float(rng.choice([0.025, 0.05, 0.1]))
    sigma = float(rng.choice([0.03, 0.07, 0.2]))
    n = int(rng.integers(1, 300))
    # walls (dense lines) and scattered points
    pts = [rng.uniform(-3.0, 3.0, (n, 2))]
    for _ in range(int(rng.integers(0, 4))):
        a, b = rng.uniform(-3.0, 3.0, 2), rng.uniform(-3.0, 3.0, 2)
        u = np.linspace(0.0, 1.0, 150)[:, None]
        pts.append(a + u * (b - a))
    return LikelihoodField(np.vstack(pts), res, sigma, margin=float(rng.uniform(0.0, 1.0)))


def random_case(rng: np.random.Generator):
    field = random_field(rng)
    n = int(rng.integers(10, 401))
    pts = rng.uniform(-3.5, 3.5, (n, 2))
    far = rng.random(n) < 0.1                                 # some beams far outside the field
    pts[far] *= 5.0
    prior = Pose2D(*rng.uniform(-1.5, 1.5, 2), rng.uniform(-math.pi, math.pi))
    yaw = float(rng.uniform(0.0, math.pi))
    window = SearchWindow(float(rng.uniform(0.0, 1.5)), yaw, float(rng.choice([0.0175, 0.035, 0.1])))
    prior_sigma = None if rng.random() < 0.5 else (float(rng.uniform(0.02, 1.0)), float(rng.uniform(0.02, 2.0)))
    return field, pts, prior, window, prior_sigma, float(rng.choice([1.0, 10.0, 30.0]))


@pytest.mark.parametrize("seed", range(40))
def test_branch_and_bound_equals_exhaustive_on_random_scenes(seed):
    rng = np.random.default_rng(seed)
    field, pts, prior, window, prior_sigma, bpd = random_case(rng)
    bnb, exh = coarse_pair(field, pts, prior, window, prior_sigma, bpd)
    assert bnb[:3] == exh[:3]                                 # the same candidate: exact indices
    assert bnb[3] == pytest.approx(exh[3], abs=1e-9)
    assert_same(match(field, pts, prior, window, prior_sigma, bpd),
                match_exhaustive(field, pts, prior, window, prior_sigma, bpd))


@pytest.mark.parametrize("seed", range(40, 60))
def test_branch_and_bound_equals_exhaustive_with_a_capped_prior(seed):
    """The capped (robust) prior keeps the bound valid: its penalty never falls with the distance."""
    rng = np.random.default_rng(seed)
    field, pts, prior, window, _, bpd = random_case(rng)
    sigma, cap = (float(rng.uniform(0.02, 0.3)), float(rng.uniform(0.02, 0.3))), float(rng.uniform(0.5, 8.0))
    co = scan_matcher._coarse(field, pts, prior, window)
    rank = scan_matcher._Ranking(field.res, co.dths, window, len(pts), sigma, bpd, cap)
    bnb, exh = scan_matcher._search_bnb(field, co, rank), scan_matcher._search_exhaustive(field, co, rank)
    assert bnb[:3] == exh[:3]
    assert_same(match(field, pts, prior, window, sigma, bpd, cap), match_exhaustive(field, pts, prior, window, sigma,
                                                                                     bpd, cap))


def test_a_capped_prior_believes_a_scan_that_fits_far_better_after_a_slip():
    """The odometry says the robot turned 8 deg more than it did (wheels slipping in a spin) and is sure to
    1.5 deg: the Gaussian prior keeps the match near the odometry's heading; capped at 4.5 nats (3 sigma),
    the scan that fits far better wins.  A prediction that is right stays right either way."""
    truth = Pose2D(-0.6, 0.4, 0.7)
    walls, pts = room_scan(truth)
    field = LikelihoodField(walls, 0.05, 0.05)
    window = SearchWindow(0.25, 0.25, 0.0175)
    sigma = (0.03, math.radians(1.5))
    slipped = Pose2D(truth.x, truth.y, truth.yaw + math.radians(8.0))
    gauss = match(field, pts, slipped, window, sigma, 30.0)
    robust = match(field, pts, slipped, window, sigma, 30.0, 4.5)
    assert abs(gauss.pose.yaw - truth.yaw) > math.radians(3.0)
    assert abs(robust.pose.yaw - truth.yaw) < math.radians(0.5) and robust.pose.distance(truth) < 0.05
    right = Pose2D(truth.x + 0.01, truth.y, truth.yaw + math.radians(0.5))
    a, b = match(field, pts, right, window, sigma, 30.0), match(field, pts, right, window, sigma, 30.0, 4.5)
    assert a.pose.distance(b.pose) < 1e-9 and abs(a.pose.yaw - b.pose.yaw) < 1e-9


def room_scan(pose: Pose2D, n: int = 180) -> tuple[np.ndarray, np.ndarray]:
    """Obstacle points of a 6 x 4 m room with a pillar, and the beam ends seen from ``pose`` (base frame)."""
    from chefbot_navigation.slam.synthetic import box_segments, cast
    segs = np.vstack((box_segments(-3.0, -2.0, 3.0, 2.0), box_segments(0.8, 0.3, 1.3, 0.9)))
    u = np.linspace(0.0, 1.0, 120)[:, None]
    walls = np.vstack([s[:2] + u * (s[2:] - s[:2]) for s in segs])
    ang = np.linspace(-math.pi, math.pi, n, endpoint=False)
    r = cast(segs, (pose.x, pose.y), ang + pose.yaw, 10.0)
    ok = np.isfinite(r)
    return walls, np.column_stack((r[ok] * np.cos(ang[ok]), r[ok] * np.sin(ang[ok])))


@pytest.mark.parametrize("prior_sigma", [None, (0.2, 0.5), (5.0, 5.0)])
@pytest.mark.parametrize("xy,yaw", [(0.25, 0.25), (1.0, math.pi), (1.5, 1.0)])
def test_room_scene_equal_and_correct(prior_sigma, xy, yaw):
    truth = Pose2D(-0.6, 0.4, 0.7)
    walls, pts = room_scan(truth)
    field = LikelihoodField(walls, 0.05, 0.07)
    prior = Pose2D(truth.x + 0.12, truth.y - 0.08, truth.yaw + 0.1)
    window = SearchWindow(xy, yaw, 0.035)
    a = match(field, pts, prior, window, prior_sigma, 30.0)
    assert_same(a, match_exhaustive(field, pts, prior, window, prior_sigma, 30.0))
    assert a.pose.distance(truth) < 0.08                     # the matcher finds the room (not the point here)


@pytest.mark.parametrize("prior_sigma", [None, (0.3, 0.3)])
def test_ties_on_a_constant_field_follow_argmax(prior_sigma):
    """Every cell of an all-obstacle field scores 1: all candidates tie on the raw score; the ranking
    is symmetric in +-x, +-y, +-yaw, so the lowest flat index must win as with np.argmax."""
    occ = np.ones((40, 40), dtype=bool)
    field = LikelihoodField(np.zeros((0, 2)), 0.05, occupied_mask=occ, origin=(-1.0, -1.0))
    rng = np.random.default_rng(3)
    pts = rng.uniform(-0.5, 0.5, (50, 2))
    for window in (SearchWindow(0.3, 0.2, 0.05), SearchWindow(0.6, 1.0, 0.1)):
        bnb, exh = coarse_pair(field, pts, Pose2D(0.1, 0.0, 0.0), window, prior_sigma, 10.0)
        assert bnb[:3] == exh[:3]
        assert bnb[3] == pytest.approx(exh[3], abs=1e-9)


@pytest.mark.parametrize("prior_sigma", [None, (0.3, 0.4)])
def test_exact_ties_pick_the_lowest_flat_index(prior_sigma):
    """Beams at the base origin (every yaw scores the same) and four obstacle cells 5 cells off the prior
    along +-x and +-y: the candidates on them tie exactly in score and in penalty; the winner must be
    the lowest flat index (t, iy, ix) in C order, as np.argmax picks."""
    occ = np.zeros((21, 21), dtype=bool)
    occ[10, 5] = occ[10, 15] = occ[5, 10] = occ[15, 10] = True
    field = LikelihoodField(np.zeros((0, 2)), 0.1, sigma=0.02, occupied_mask=occ, origin=(0.0, 0.0))
    pts = np.zeros((3, 2))
    prior = Pose2D(1.05, 1.05, 0.0)                       # the centre of cell (10, 10)
    window = SearchWindow(0.7, 0.3, 0.1)
    bnb, exh = coarse_pair(field, pts, prior, window, prior_sigma, 1.0)
    assert bnb[:3] == exh[:3]
    assert bnb[3] == pytest.approx(exh[3], abs=1e-9)
    co = scan_matcher._coarse(field, pts, prior, window)
    rank = scan_matcher._Ranking(field.res, co.dths, window, len(pts), prior_sigma, 1.0)
    d, n = len(co.offs), co.n_xy
    t, y, x = (a.ravel() for a in np.meshgrid(np.arange(len(co.dths)), np.arange(d), np.arange(d), indexing="ij"))
    values = rank.leaf(t, y - n, x - n, scan_matcher._block_raw(field, 0, co, t, y - n, x - n))
    ties = np.nonzero(values == values.max())[0]
    assert len(ties) == 4                                     # one yaw (the prior's), the four obstacle cells
    assert (bnb[0] * d + bnb[1]) * d + bnb[2] == ties[0]
    assert (bnb[0], bnb[1], bnb[2]) == (co.n_th, n - 5, n)    # -y is the lowest row


@pytest.mark.parametrize("seed", range(6))
def test_windows_past_the_field_edge(seed):
    """The prior near a corner of a small field, the window reaching far beyond it: indices are clipped."""
    rng = np.random.default_rng(100 + seed)
    pts_map = rng.uniform(0.0, 0.6, (30, 2))
    field = LikelihoodField(pts_map, 0.05, 0.05, margin=0.1)
    pts = rng.uniform(-0.4, 0.4, (int(rng.integers(10, 200)), 2))
    prior = Pose2D(float(rng.uniform(-0.2, 0.9)), float(rng.uniform(-0.2, 0.9)), 0.0)
    window = SearchWindow(1.5, float(rng.uniform(0.0, math.pi)), 0.1)
    prior_sigma = None if seed % 2 else (0.5, 1.0)
    bnb, exh = coarse_pair(field, pts, prior, window, prior_sigma, 10.0)
    assert bnb[:3] == exh[:3]
    assert bnb[3] == pytest.approx(exh[3], abs=1e-9)
    assert_same(match(field, pts, prior, window, prior_sigma, 10.0),
                match_exhaustive(field, pts, prior, window, prior_sigma, 10.0))


@pytest.mark.parametrize("seed", range(4))
def test_block_bounds_dominate_every_candidate_even_clipped(seed):
    """The raw bound of every block at every depth >= the raw score of each candidate inside it."""
    rng = np.random.default_rng(200 + seed)
    field = random_field(rng)
    h, w = field.field.shape
    pts = rng.uniform(-6.0, 6.0, (int(rng.integers(10, 100)), 2))    # many beams clipped
    co = scan_matcher._coarse(field, pts, Pose2D(0.0, 0.0, 0.3), SearchWindow(max(h, w) * field.res / 2, 0.1, 0.1))
    n, d = co.n_xy, len(co.offs)
    for depth in range(0, 5):
        size = 1 << depth
        t, y0, x0 = (a.ravel() for a in np.meshgrid(np.arange(len(co.dths)), np.arange(0, d, 3),
                                                    np.arange(0, d, 3), indexing="ij"))
        ub = scan_matcher._block_raw(field, depth, co, t, y0 - n, x0 - n)
        for dy in range(size):
            for dx in range(size):
                ok = (y0 + dy < d) & (x0 + dx < d)
                raw = scan_matcher._block_raw(field, 0, co, t[ok], y0[ok] + dy - n, x0[ok] + dx - n)
                assert (ub[ok] >= raw).all()


@pytest.mark.parametrize("depth", [1, 2, 3, 5])
def test_max_pooled_grid_dominates_every_cell_it_covers(depth):
    rng = np.random.default_rng(depth)
    field = random_field(rng)
    grid = field.max_pooled(depth)
    assert grid.shape == field.field.shape
    assert field.max_pooled(depth) is grid                    # cached
    size = 1 << depth
    f = field.field
    h, w = f.shape
    for r in range(0, h, 7):
        for c in range(0, w, 5):
            block = f[r:r + size, c:c + size]
            assert grid[r, c] == block.max()                 # the max of the covered cells, no more
    with pytest.raises(ValueError):
        field.max_pooled(-1)


def test_flat_bound_with_negative_factors():
    """score * f for 0 <= score <= ub and f <= factor: with factor < 0 the bound is 0 (score may be 0)."""
    rng = np.random.default_rng(7)
    ub = rng.uniform(0.0, 1.0, 1000).astype(np.float32)
    factor = rng.uniform(-2.0, 1.0, 1000)
    bound = scan_matcher._flat_bound(ub, factor)
    for frac in (0.0, 0.3, 1.0):
        score = (ub * np.float32(frac)).astype(np.float32)
        for shrink in (0.0, 0.5, 3.0):
            f = factor - shrink
            assert (bound >= score * f).all()
    assert (bound[factor < 0] == 0.0).all()
    assert np.allclose(bound[factor >= 0], ub[factor >= 0] * factor[factor >= 0])


def test_ranking_bound_dominates_every_candidate_of_a_block():
    """The rank bound over a block (nearest offset, ub) >= the rank of every candidate with raw <= ub."""
    rng = np.random.default_rng(11)
    dths = np.linspace(-1.0, 1.0, 21)
    for prior_sigma in (None, (0.1, 0.2), (2.0, 3.0)):
        rank = scan_matcher._Ranking(0.05, dths, SearchWindow(0.5, 1.0, 0.1), 300, prior_sigma, 30.0)
        for _ in range(50):
            t = rng.integers(0, 21, 1)
            oy0, ox0 = rng.integers(-40, 40, 2)
            size = int(rng.choice([1, 2, 4, 8, 32]))
            ub = rng.uniform(0.0, 1.0, 1).astype(np.float32)
            b = rank.bound(t, np.array([oy0]), np.array([oy0 + size - 1]), np.array([ox0]),
                           np.array([ox0 + size - 1]), ub)
            oy, ox = np.meshgrid(np.arange(oy0, oy0 + size), np.arange(ox0, ox0 + size))
            raw = (ub * rng.uniform(0.0, 1.0, oy.size)).astype(np.float32)
            raw[0] = ub[0]
            leaf = rank.leaf(np.repeat(t, oy.size), oy.ravel(), ox.ravel(), raw)
            assert (b >= leaf).all()


def test_empty_scan_and_zero_window():
    field = LikelihoodField(np.array([[0.0, 0.0], [1.0, 0.0]]), 0.05)
    assert match(field, np.zeros((0, 2)), Pose2D(0.0, 0.0, 0.0), SearchWindow()).beams == 0
    pts = np.array([[0.5, 0.1], [0.2, -0.3]])
    for window in (SearchWindow(0.0, 0.0, 0.1), SearchWindow(0.0, 0.5, 0.1), SearchWindow(0.5, 0.0, 0.1)):
        assert_same(match(field, pts, Pose2D(0.1, 0.0, 0.2), window),
                    match_exhaustive(field, pts, Pose2D(0.1, 0.0, 0.2), window))
