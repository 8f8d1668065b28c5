"""Wheel odometry noise: the model's moments, and in the simulator: odometry drifts, ground truth does not,
same seed same drift, snapshots carry the noise state."""
import math

import numpy as np
import pytest
from test_sim import WALL, drive

from chefbot_sim.sim import SimConfigError, SimOptions, Simulator
from chefbot_sim.wheel_noise import WheelNoise, measure_wheels, quantise

R = 0.045


def test_radius_error_scales_and_standing_still_never_drifts() -> None:
    n = WheelNoise(0.01, -0.02, 0.0)
    m = measure_wheels(n, np.random.default_rng(0), (0.0, 0.0), (10.0, 10.0), (1.0, 2.0), R)
    assert m == pytest.approx((1.0 + 10.0 / 1.01, 2.0 + 10.0 / 0.98))
    slip = WheelNoise(slip_stddev=0.01)
    assert measure_wheels(slip, np.random.default_rng(0), (3.0, 4.0), (3.0, 4.0), (5.0, 6.0), R) == (5.0, 6.0)


def test_slip_variance_grows_with_distance_not_with_step_count() -> None:
    noise = WheelNoise(slip_stddev=0.01)
    rng = np.random.default_rng(1)
    dist = 4.0                       # m rolled
    for steps in (1, 50):
        finals = []
        for _ in range(2000):
            true, meas = (0.0, 0.0), (0.0, 0.0)
            for k in range(1, steps + 1):
                now = (dist / R * k / steps,) * 2
                meas = measure_wheels(noise, rng, true, now, meas, R)
                true = now
            finals.append(meas[0] * R - dist)
        assert np.std(finals) == pytest.approx(0.01 * math.sqrt(dist), rel=0.08)


def test_quantise_to_encoder_counts() -> None:
    step = 2 * math.pi / 8400
    assert quantise(10.5 * step, 8400) == pytest.approx(10 * step)
    assert quantise(-0.5 * step, 8400) == pytest.approx(-step)
    assert quantise(0.123, 0) == 0.123


def test_bad_noise_settings_are_named(urdf) -> None:
    with pytest.raises(SimConfigError, match="slip_stddev"):
        Simulator(urdf, WALL, options=SimOptions(wheel_slip_stddev=-1.0))


NOISY = dict(wheel_radius_error_left=0.01, wheel_radius_error_right=-0.01, wheel_slip_stddev=0.01,
             wheel_encoder_counts=8400)


def run_square(urdf, **kw) -> tuple[tuple, tuple]:
    s = Simulator(urdf, WALL, options=SimOptions(seed=5, **kw))
    try:
        drive(s, 0.25, 0.0, 3.0)
        drive(s, 0.0, 1.0, 1.6)
        drive(s, 0.25, 0.3, 3.0)
        gt = s.ground_truth()
        return (gt["x"], gt["y"], gt["yaw"]), s.s.odom
    finally:
        s.close()


def test_odometry_drifts_and_ground_truth_does_not(urdf) -> None:
    gt_clean, odom_clean = run_square(urdf)
    gt_noisy, odom_noisy = run_square(urdf, **NOISY)
    assert gt_noisy == pytest.approx(gt_clean, abs=1e-9)          # physics untouched
    err_clean = math.hypot(odom_clean[0] - gt_clean[0], odom_clean[1] - gt_clean[1])
    err_noisy = math.hypot(odom_noisy[0] - gt_noisy[0], odom_noisy[1] - gt_noisy[1])
    assert err_noisy > err_clean + 0.02
    assert abs(math.remainder(odom_noisy[2] - gt_noisy[2], 2 * math.pi)) > 0.03
    assert run_square(urdf, **NOISY)[1] == odom_noisy             # same seed, same drift


def test_snapshot_restores_the_wheel_noise(urdf) -> None:
    s = Simulator(urdf, WALL, options=SimOptions(seed=2, **NOISY))
    try:
        drive(s, 0.2, 0.2, 0.5)
        snap = s.snapshot()
        drive(s, 0.2, -0.3, 1.0)
        first = s.s.odom
        s.restore(snap)
        drive(s, 0.2, -0.3, 1.0)
        assert s.s.odom == first
    finally:
        s.close()


def test_odom_imu_heading_keeps_the_heading_the_wheels_lose(urdf) -> None:
    """Plugin drive with ``odom_imu_heading``: the heading is the IMU's (only its small gyro drift),
    while the wheels' heading error grows with the turning; the position still comes from the wheels."""
    gt, wheels = run_square(urdf, **NOISY)
    gt_imu, imu = run_square(urdf, odom_imu_heading=True, **NOISY)
    assert gt_imu == pytest.approx(gt, abs=1e-9)                  # physics untouched
    yaw_err = lambda odom, truth: abs(math.remainder(odom[2] - truth[2], 2 * math.pi))  # noqa: E731
    assert yaw_err(wheels, gt) > 0.03
    assert yaw_err(imu, gt_imu) < 0.005                           # 0.0003 rad/s bias over ~8 s
    pos_err = math.hypot(imu[0] - gt_imu[0], imu[1] - gt_imu[1])
    assert 0.0 < pos_err < math.hypot(wheels[0] - gt[0], wheels[1] - gt[1])

