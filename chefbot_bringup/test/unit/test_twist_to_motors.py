"""Twist -> wheel targets: kinematics, clamping, timeout, no stutter at 5 Hz, sonar."""
import math

import pytest

from chefbot_bringup.safety import SonarLimitConfig, SonarLimiter
from chefbot_bringup.twist_to_motors import (
    TwistToMotors,
    TwistToMotorsConfig,
    wheel_speeds,
)


def test_kinematics_left_turn():
    left, right = wheel_speeds(0.1, 1.0, 0.30, 10.0)
    assert (left, right) == pytest.approx((0.1 - 0.15, 0.1 + 0.15))


def test_clamp_keeps_turn_ratio():
    left, right = wheel_speeds(0.3, 1.0, 0.30, 0.377)
    assert max(abs(left), abs(right)) == pytest.approx(0.377)
    assert left / right == pytest.approx(0.15 / 0.45)


BIG = 1.7e308


@pytest.mark.parametrize("v,w", [(BIG, BIG), (-BIG, BIG), (BIG, -BIG), (-BIG, -BIG), (BIG, 0.0), (0.0, BIG),
                                 (1e-300, BIG), (BIG, 1e-300), (5e307, 1e308), (1e200, 3.0)])
def test_huge_commands_saturate_instead_of_overflowing(v, w):
    for max_speed in (0.377, 10.0):
        left, right = wheel_speeds(v, w, 0.30, max_speed)
        assert math.isfinite(left) and math.isfinite(right), (v, w, left, right)
        assert max(abs(left), abs(right)) == pytest.approx(max_speed)
        # the direction of the command survives: forward/backward and turn sense
        if w == 0.0:
            assert left == right and math.copysign(1, left) == math.copysign(1, v)
        elif abs(w) * 0.15 > abs(v):
            assert math.copysign(1, right - left) == math.copysign(1, w)


def test_huge_command_through_the_core_every_tick_finite_and_limited():
    cfg = TwistToMotorsConfig()
    limiter = SonarLimiter(SonarLimitConfig())
    limiter.add_range(math.inf, 0.02, 4.0, 0.0)
    t2m = TwistToMotors(cfg, limiter)
    assert t2m.set_twist(BIG, BIG)
    for i in range(cfg.timeout_ticks):
        left, right = t2m.tick(i / cfg.rate)
        assert math.isfinite(left) and math.isfinite(right)
        assert max(abs(left), abs(right)) <= cfg.max_wheel_speed + 1e-12


def test_nan_and_inf_ignored():
    t2m = TwistToMotors(TwistToMotorsConfig())
    assert t2m.set_twist(0.1, 0.0)
    assert not t2m.set_twist(math.nan, 0.0)
    assert not t2m.set_twist(0.1, math.inf)
    assert t2m.v == 0.1


def simulate(cmd_period: float, n_cmds: int, cfg: TwistToMotorsConfig, jitter: float = 0.0):
    """Commands every cmd_period s; returns the list of (t, output) per tick."""
    t2m = TwistToMotors(cfg)
    out = []
    cmd_times = [k * cmd_period + (jitter if k % 2 else 0.0) for k in range(n_cmds)]
    k = 0
    for i in range(int((cmd_times[-1] + 2.0) * cfg.rate)):
        t = i / cfg.rate
        while k < len(cmd_times) and cmd_times[k] <= t:
            t2m.set_twist(0.2, 0.0)
            k += 1
        out.append((t, t2m.tick(t)))
    return out, cmd_times[-1]


@pytest.mark.parametrize("jitter", [0.0, 0.08])
def test_no_stutter_at_5hz_and_stop_within_half_a_second(jitter):
    cfg = TwistToMotorsConfig()
    out, last = simulate(0.2, 20, cfg, jitter)
    during = [o for t, o in out if 0.0 <= t <= last]
    assert all(o is not None and o[0] > 0 for o in during)
    zero_at = next(t for t, o in out if t > last and o == (0.0, 0.0))
    assert zero_at - last <= 0.5
    assert all(o is None for t, o in out if t > zero_at)


def test_book_defaults_would_stutter():
    out, last = simulate(0.2, 20, TwistToMotorsConfig(timeout_ticks=2))
    assert any(o == (0.0, 0.0) for t, o in out if t < last)


def test_default_stop_delay_budget():
    cfg = TwistToMotorsConfig()
    assert 0.2 * 1.5 < cfg.stop_delay <= 0.4


def limiter() -> SonarLimiter:
    return SonarLimiter(SonarLimitConfig(stop_distance=0.25, slow_distance=0.6, timeout=0.5, stale_speed=0.1))


def test_sonar_stop_slow_clear():
    lim = limiter()
    lim.add_range(0.2, 0.02, 4.0, 0.0)
    assert lim.limit(0.3, 0.1) == 0.0
    assert lim.limit(-0.2, 0.1) == -0.2          # reversing allowed
    lim.add_range(0.425, 0.02, 4.0, 0.2)
    assert lim.limit(0.3, 0.3) == pytest.approx(0.15)
    lim.add_range(1.0, 0.02, 4.0, 0.4)
    assert lim.limit(0.3, 0.5) == 0.3
    lim.add_range(math.inf, 0.02, 4.0, 0.6)
    assert lim.limit(0.3, 0.7) == 0.3
    lim.add_range(-math.inf, 0.02, 4.0, 0.8)
    assert lim.limit(0.3, 0.9) == 0.0


def test_sonar_no_echo_and_nan_carry_no_information():
    lim = limiter()
    lim.add_range(0.2, 0.02, 4.0, 0.0)
    assert not lim.add_range(0.0, 0.02, 4.0, 0.1)     # HC-SR04 "no echo"
    assert not lim.add_range(math.nan, 0.02, 4.0, 0.1)
    assert lim.limit(0.3, 0.2) == 0.0                 # still the last real reading


def test_stale_sonar_creeps_but_is_not_clear():
    lim = limiter()
    assert lim.limit(0.3, 0.0) == pytest.approx(0.1)   # never heard from
    lim.add_range(0.2, 0.02, 4.0, 1.0)
    assert lim.limit(0.3, 1.2) == 0.0
    assert lim.limit(0.3, 2.0) == pytest.approx(0.1)   # stale: creep


def test_twist_to_motors_with_sonar_turns_in_place_when_blocked():
    lim = limiter()
    t2m = TwistToMotors(TwistToMotorsConfig(), lim)
    lim.add_range(0.1, 0.02, 4.0, 0.0)
    t2m.set_twist(0.3, 1.0)
    left, right = t2m.tick(0.02)
    assert left == pytest.approx(-right) and right > 0


def test_bad_sonar_config():
    with pytest.raises(ValueError, match="stop_distance"):
        SonarLimitConfig(stop_distance=0.7, slow_distance=0.6)


def test_current_gives_the_new_command_without_counting_a_tick():
    core = TwistToMotors(TwistToMotorsConfig(timeout_ticks=2))
    assert core.current(0.0) is None                # silent before the first command
    core.set_twist(0.1, 0.0)
    for _ in range(5):
        assert core.current(0.0) == pytest.approx((0.1, 0.1))
    assert core.tick(0.02) == pytest.approx((0.1, 0.1))
    assert core.tick(0.04) == (0.0, 0.0)            # the 2nd tick times out, as without current()
    assert core.current(0.05) is None
