"""The MPU6050 heading model: yaw relative to the start pose, gyro bias and its drift."""
import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D, yaw_from_quaternion
from chefbot_sim import imu_model
from chefbot_sim.imu_model import ImuDriftConfig
from chefbot_sim.sim import SimConfigError, SimOptions, Simulator
from chefbot_sim.world import parse_yaml_world

EMPTY = parse_yaml_world("objects: []")
STEPS_PER_S = 240


def imu_events(sim: Simulator, w: float, seconds: float) -> list:
    ev = []
    for _ in range(int(round(seconds / 0.1))):
        sim.set_cmd_vel(0.0, w)
        ev += [e for e in sim.step(24) if e.kind == "imu"]
    return ev


def test_yaw_starts_at_zero_wherever_the_robot_stands_and_follows_turns(urdf):
    opts = SimOptions(seed=1, imu_gyro_bias=0.0, imu_gyro_bias_drift=0.0)
    sim = Simulator(urdf, EMPTY, Pose2D(1.0, 2.0, 2.5), options=opts)
    try:
        first = imu_events(sim, 0.0, 0.5)[-1].data
        assert yaw_from_quaternion(*first["orientation"]) == pytest.approx(0.0, abs=1e-3)
        imu_events(sim, 0.8, 1.5)
        last = imu_events(sim, 0.0, 1.0)[-1].data
        turned = sim.ground_truth()["yaw"] - 2.5
        got = yaw_from_quaternion(*last["orientation"])
        assert abs(turned) > 0.5
        assert math.remainder(got - turned, math.tau) == pytest.approx(0.0, abs=2e-3)
    finally:
        sim.close()


def test_absolute_yaw_when_asked(urdf):
    opts = SimOptions(seed=1, imu_relative_yaw=False, imu_gyro_bias=0.0, imu_gyro_bias_drift=0.0)
    sim = Simulator(urdf, EMPTY, Pose2D(0.0, 0.0, 1.0), options=opts)
    try:
        q = imu_events(sim, 0.0, 0.3)[-1].data["orientation"]
        assert yaw_from_quaternion(*q) == pytest.approx(1.0, abs=1e-3)
    finally:
        sim.close()


def test_constant_bias_drifts_the_heading_at_rest(urdf):
    opts = SimOptions(seed=1, imu_gyro_bias=0.01, imu_gyro_bias_drift=0.0)
    sim = Simulator(urdf, EMPTY, options=opts)
    try:
        ev = imu_events(sim, 0.0, 5.0)
        yaw = yaw_from_quaternion(*ev[-1].data["orientation"])
        t0, t1 = ev[0].stamp, ev[-1].stamp
        assert yaw == pytest.approx(0.01 * (t1 - t0), abs=2e-3)     # the robot did not turn
        assert abs(sim.ground_truth()["yaw"]) < 1e-3
        assert np.mean([e.data["angular_velocity"][2] for e in ev]) == pytest.approx(0.01, abs=0.003)
    finally:
        sim.close()


def test_bias_random_walk_has_the_configured_density():
    cfg = ImuDriftConfig(gyro_bias=0.0, gyro_bias_drift=0.002)
    finals = []
    for seed in range(300):
        st = imu_model.initial_state(cfg)
        for k in range(101):                       # 10 s at 10 Hz
            st = imu_model.advance(st, 0.1 * k, cfg, seed)
        finals.append(st[0])
    assert np.std(finals) == pytest.approx(0.002 * math.sqrt(10.0), rel=0.15)
    assert abs(np.mean(finals)) < 0.002


def test_advance_is_a_pure_function_of_state_time_and_seed():
    cfg = ImuDriftConfig()
    st = imu_model.advance(imu_model.initial_state(cfg), 0.0, cfg, 4)
    a = imu_model.advance(st, 0.02, cfg, 4)
    b = imu_model.advance(st, 0.02, cfg, 4)
    assert a == b and a != imu_model.advance(st, 0.02, cfg, 5)
    assert imu_model.advance(a, 0.01, cfg, 4) == (a[0], a[1], 0.01, a[3])   # time going back: no step


@pytest.mark.parametrize("field,value", [("imu_gyro_bias", math.nan), ("imu_gyro_bias_drift", -1.0)])
def test_bad_drift_params_are_named(urdf, field, value):
    with pytest.raises(SimConfigError, match=field):
        Simulator(urdf, EMPTY, options=SimOptions(**{field: value}))
