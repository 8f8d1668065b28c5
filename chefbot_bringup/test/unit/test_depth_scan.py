"""depth_to_scan core against geometry and against the per-pixel reference."""
import math

import numpy as np
import pytest

from chefbot_bringup.depth_scan import (
    Intrinsics,
    ScanConfig,
    column_bins,
    depth_to_scan,
    depth_to_scan_reference,
    scan_rows,
)

W, H = 640, 480
CAM = Intrinsics(fx=570.3, cx=319.5, cy=239.5, width=W, height=H)
CFG = ScanConfig(scan_height=10, range_min=0.45, range_max=10.0)


def angles(scan) -> np.ndarray:
    return scan.angle_min + scan.angle_increment * np.arange(len(scan.ranges))


def wall(d: float) -> np.ndarray:
    return np.full((H, W), d, dtype=np.float32)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    return np.array_equal(a, b, equal_nan=True)


def test_angles_leftmost_column_is_most_positive():
    scan = depth_to_scan(wall(2.0), CAM, CFG)
    assert scan.angle_max == pytest.approx(math.atan(319.5 / 570.3), abs=1e-6)
    assert scan.angle_min == pytest.approx(-math.atan(319.5 / 570.3), abs=1e-6)
    bins = column_bins(CAM)
    assert bins[0] >= W - 2 and bins[-1] == 0
    assert np.all(np.diff(bins) <= 0)


@pytest.mark.parametrize("d", [0.5, 2.0, 7.5])
def test_flat_wall_ranges_follow_one_over_cos(d):
    scan = depth_to_scan(wall(d), CAM, CFG)
    a = angles(scan).astype(np.float64)
    r = scan.ranges.astype(np.float64)
    ok = np.isfinite(r)
    assert ok.sum() > 0.9 * W     # a few bins get no column, as upstream
    # Each bin holds a ray whose bearing lies in [a, a + increment).
    lo = d / np.cos(np.minimum(np.abs(a), np.abs(a + scan.angle_increment)))
    hi = d / np.cos(np.maximum(np.abs(a), np.abs(a + scan.angle_increment)))
    assert np.all(r[ok] >= lo[ok] - 1e-3) and np.all(r[ok] <= hi[ok] + 1e-3)
    # At the centre the range is the depth.
    centre = np.argmin(np.abs(a))
    assert r[centre] == pytest.approx(d, abs=1e-3)


def test_box_at_known_bearing():
    depth = wall(4.0)
    u0, u1 = 100, 140       # box columns, left of centre -> positive bearing
    depth[:, u0:u1] = 1.5
    scan = depth_to_scan(depth, CAM, CFG)
    a = angles(scan)
    hit = np.where(scan.ranges < 3.0)[0]
    bearing_lo = -math.atan((u1 - 1 - CAM.cx) / CAM.fx)
    bearing_hi = -math.atan((u0 - CAM.cx) / CAM.fx)
    assert a[hit].min() >= bearing_lo - scan.angle_increment
    assert a[hit].max() <= bearing_hi + scan.angle_increment
    mid = hit[len(hit) // 2]
    assert scan.ranges[mid] == pytest.approx(1.5 / math.cos(a[mid]), abs=2e-3)
    assert a[mid] > 0


def test_nearest_row_wins():
    depth = wall(3.0)
    depth[240, :] = 2.0
    assert np.nanmax(depth_to_scan(depth, CAM, CFG).ranges) < 2.5


def test_invalid_values():
    depth = wall(3.0)
    band = slice(*scan_rows(CAM, CFG.scan_height))
    # Columns near the centre, where each bin gets at most one column.
    depth[band, 290] = np.nan                # no return
    depth[band, 300] = 0.0                   # float zero: never in range
    depth[band, 310] = np.inf                # nothing within range
    depth[band, 320] = 0.2                   # closer than range_min
    depth[band, 330] = 20.0                  # farther than range_max
    depth[band, 340] = np.nan
    depth[band.start, 340] = 2.0             # one good row is enough
    depth[band, 350] = -np.inf
    depth[band.stop - 1, 350] = np.inf        # the last infinity in row-major order wins
    scan = depth_to_scan(depth, CAM, CFG)
    bins = column_bins(CAM)
    assert len(set(bins[285:355])) == 70
    for col in (290, 300, 320, 330):
        assert np.isnan(scan.ranges[bins[col]]), col
    assert scan.ranges[bins[310]] == np.inf
    assert scan.ranges[bins[340]] == pytest.approx(2.0 * math.hypot(1, (340 - CAM.cx) / CAM.fx), abs=1e-3)
    assert scan.ranges[bins[350]] == np.inf
    assert same(scan.ranges, depth_to_scan_reference(depth, CAM, CFG).ranges)


def test_uint16_millimetres_equal_float_metres():
    mm = np.full((H, W), 2000, dtype=np.uint16)
    mm[:, 300:310] = 0                       # no data
    m = mm.astype(np.float32) / 1000
    m[mm == 0] = np.nan
    a = depth_to_scan(mm, CAM, CFG).ranges
    b = depth_to_scan(m, CAM, CFG).ranges
    assert np.allclose(a, b, equal_nan=True, atol=1e-6)
    assert same(a, depth_to_scan_reference(mm, CAM, CFG).ranges)


@pytest.mark.parametrize("h", [1, 2, 9, 10, 11, 480, 1000])
def test_scan_height_rows_and_clipping(h):
    r0, r1 = scan_rows(CAM, h)
    assert 0 <= r0 < r1 <= H
    assert r1 - r0 == min(h, H) or h > H
    # A bar one row outside the band must not show up; one inside must.
    depth = wall(4.0)
    if r0 > 0:
        depth[r0 - 1] = 1.0
    if r1 < H:
        depth[r1] = 1.0
    assert np.nanmin(depth_to_scan(depth, CAM, CFG.__class__(scan_height=h)).ranges) > 3.9
    depth[r1 - 1] = 1.0
    assert np.nanmin(depth_to_scan(depth, CAM, CFG.__class__(scan_height=h)).ranges) < 1.1


def test_band_near_border_clipped():
    cam = Intrinsics(fx=300.0, cx=80.0, cy=3.0, width=160, height=120)
    assert scan_rows(cam, 10) == (0, 8)
    depth = np.full((120, 160), 1.0, dtype=np.float32)
    assert np.isfinite(depth_to_scan(depth, cam, ScanConfig(scan_height=10)).ranges).sum() > 100


@pytest.mark.parametrize("seed", [0, 1, 2])
@pytest.mark.parametrize("h", [1, 10, 25])
def test_identical_to_reference_on_random_images(seed, h):
    rng = np.random.default_rng(seed)
    cam = Intrinsics(fx=200.0 + seed * 50, cx=79.3, cy=60.7, width=160, height=120)
    depth = rng.uniform(0.1, 12.0, (120, 160)).astype(np.float32)
    mask = rng.random(depth.shape)
    depth[mask < 0.05] = np.nan
    depth[(mask > 0.05) & (mask < 0.08)] = np.inf
    depth[(mask > 0.08) & (mask < 0.1)] = -np.inf
    depth[(mask > 0.1) & (mask < 0.12)] = 0.0
    cfg = ScanConfig(scan_height=h)
    assert same(depth_to_scan(depth, cam, cfg).ranges, depth_to_scan_reference(depth, cam, cfg).ranges)


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("range_min,range_max", [(0.45, 10.0), (0.0, 3.0), (0.3, 0.3000001)])
def test_identical_to_reference_at_the_range_limits(dtype, range_min, range_max):
    """Depths whose ray length falls on, just inside and just outside range_min/range_max:
    the squared-range bounds of the fast path must agree with sqrt() compared to the limits."""
    rng = np.random.default_rng(7)
    cam = Intrinsics(fx=120.0, cx=63.5, cy=20.0, width=128, height=40)
    tan = (np.arange(128) - cam.cx) / cam.fx
    depth = np.empty((40, 128), dtype=dtype)
    for v in range(40):
        limit = range_min if v % 2 else range_max
        z = limit / np.sqrt(1.0 + tan * tan)                 # ray length == limit, up to rounding
        steps = rng.integers(-3, 4, 128)
        depth[v] = np.nextafter(z.astype(dtype), np.where(steps > 0, np.inf, 0.0).astype(dtype))
        depth[v][steps == 0] = z.astype(dtype)[steps == 0]
    depth[5, :20] = np.inf                                 # some bins with no in-range value at all
    cfg = ScanConfig(scan_height=40, range_min=range_min, range_max=range_max)
    for h in (1, 3, 40):
        cfg = ScanConfig(scan_height=h, range_min=range_min, range_max=range_max)
        assert same(depth_to_scan(depth, cam, cfg).ranges, depth_to_scan_reference(depth, cam, cfg).ranges)


def test_identical_to_reference_when_whole_columns_are_invalid():
    depth = wall(3.0)
    depth[:, :200] = np.inf              # beyond the far plane
    depth[:, 200:260] = -np.inf
    depth[:, 260:300] = np.nan
    depth[:, 300:320] = 0.2              # too close
    depth[235:240, 400:420] = np.inf     # inf rows above finite ones: the finite value still wins
    assert same(depth_to_scan(depth, CAM, CFG).ranges, depth_to_scan_reference(depth, CAM, CFG).ranges)
    nan_only = wall(3.0)
    nan_only[:, :300] = np.nan           # no data, no inf: the fast path alone
    assert same(depth_to_scan(nan_only, CAM, CFG).ranges, depth_to_scan_reference(nan_only, CAM, CFG).ranges)
    huge = wall(3.0).astype(np.float64)
    huge[237, :100] = 1e200              # finite depth whose range overflows to +inf
    huge[:, 100:200] = np.nan
    huge[238, 150] = 1e200
    assert same(depth_to_scan(huge, CAM, CFG).ranges, depth_to_scan_reference(huge, CAM, CFG).ranges)
    u16 = np.full((H, W), 3000, np.uint16)
    u16[:, :300] = 0
    assert same(depth_to_scan(u16, CAM, CFG).ranges, depth_to_scan_reference(u16, CAM, CFG).ranges)


def test_shape_mismatch_rejected():
    with pytest.raises(ValueError, match="camera_info"):
        depth_to_scan(np.zeros((10, 10), np.float32), CAM, CFG)


def test_intrinsics_prefer_p_and_reject_zero_focal():
    k = [500, 0, 320, 0, 500, 240, 0, 0, 1]
    p = [510, 0, 321, 0, 0, 510, 241, 0, 0, 0, 1, 0]
    cam = Intrinsics.from_matrices(k, p, 640, 480)
    assert (cam.fx, cam.cx, cam.cy) == (510, 321, 241)
    cam = Intrinsics.from_matrices(k, [0.0] * 12, 640, 480)
    assert cam.fx == 500
    with pytest.raises(ValueError, match="focal"):
        Intrinsics.from_matrices([0.0] * 9, [0.0] * 12, 640, 480)
