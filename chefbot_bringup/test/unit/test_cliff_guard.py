"""The cliff guard's pure logic: what blocks forward motion, what lets it through."""
import math

import pytest

from chefbot_bringup.cliff_guard import CliffGuard, CliffGuardConfig, reading_problem

SENSORS = ["cliff/left", "cliff/center", "cliff/right"]
FLOOR = 0.031   # m, what the sensors read on a flat floor
MIN, MAX = 0.01, 0.15


def guard_with(readings: dict[str, float], t: float = 1.0) -> CliffGuard:
    g = CliffGuard(CliffGuardConfig(drop_threshold=0.07, timeout=0.25), SENSORS)
    for name in SENSORS:
        g.add_range(name, readings.get(name, FLOOR), MIN, MAX, t, t)
    return g


def test_floor_everywhere_lets_everything_through():
    g = guard_with({})
    assert g.status(1.01, 1.01).safe
    for v in (0.3, 0.0, -0.2):
        assert g.limit(v, 1.01, 1.01)[0] == v


@pytest.mark.parametrize("reading", [math.inf, 0.2, 0.08, math.nan, 0.005])
@pytest.mark.parametrize("sensor", SENSORS)
def test_any_sensor_without_floor_blocks_forward_only(sensor, reading):
    g = guard_with({sensor: reading})
    v, st = g.limit(0.3, 1.01, 1.01)
    assert v == 0.0 and not st.safe
    assert len(st.reasons) == 1 and st.reasons[0].startswith(sensor)
    assert g.limit(-0.1, 1.01, 1.01)[0] == -0.1   # backing away passes
    assert g.limit(0.0, 1.01, 1.01)[0] == 0.0     # turning on the spot passes (w is not touched)


def test_reasons_say_why():
    assert "drop" in reading_problem(math.inf, MIN, MAX, 0.07)
    assert "drop" in reading_problem(0.2, MIN, MAX, 0.07)        # above max_range
    assert "0.080" in reading_problem(0.08, MIN, MAX, 0.07)      # beyond the threshold
    assert "NaN" in reading_problem(math.nan, MIN, MAX, 0.07)
    assert "min_range" in reading_problem(0.005, MIN, MAX, 0.07)
    assert reading_problem(-math.inf, MIN, MAX, 0.07) is None    # REP 117: floor closer than min_range
    assert reading_problem(0.07, MIN, MAX, 0.07) is None         # at the threshold: still a floor


def test_never_heard_from_is_unsafe():
    g = CliffGuard(CliffGuardConfig(), SENSORS)
    st = g.status(0.0, 0.0)
    assert not st.safe and len(st.reasons) == 3 and "no reading yet" in st.message
    g.add_range("cliff/left", FLOOR, MIN, MAX, 0.0, 0.0)
    g.add_range("cliff/center", FLOOR, MIN, MAX, 0.0, 0.0)
    st = g.status(0.0, 0.0)
    assert not st.safe and st.reasons == ("cliff/right: no reading yet",)


def test_stale_needs_both_clocks():
    g = guard_with({}, t=1.0)
    assert g.status(1.25, 1.25).safe                 # exactly the timeout: still fresh
    assert g.status(1.3, 1.1).safe                   # sim ran ahead of delivery (faster than real time)
    assert g.status(1.1, 1.3).safe                   # sim paused / slower than real time
    st = g.status(1.3, 1.3)
    assert not st.safe and all("stale" in r for r in st.reasons)
    assert g.limit(0.2, 1.3, 1.3)[0] == 0.0
    g.add_range("cliff/left", FLOOR, MIN, MAX, 1.3, 1.3)
    assert [r.split(":")[0] for r in g.status(1.3, 1.3).reasons] == ["cliff/center", "cliff/right"]


def test_recovers_when_the_floor_is_back():
    g = guard_with({"cliff/center": math.inf})
    assert g.limit(0.2, 1.0, 1.0)[0] == 0.0
    g.add_range("cliff/center", FLOOR, MIN, MAX, 1.02, 1.02)
    assert g.limit(0.2, 1.02, 1.02)[0] == 0.2


def test_reset_forgets_readings():
    g = guard_with({})
    g.reset()
    assert not g.status(1.0, 1.0).safe


@pytest.mark.parametrize("v", [math.nan, math.inf, -math.inf])
def test_non_finite_command_becomes_zero(v):
    assert guard_with({}).limit(v, 1.0, 1.0)[0] == 0.0


def test_unknown_sensor_is_named():
    with pytest.raises(KeyError, match="cliff/rear"):
        guard_with({}).add_range("cliff/rear", FLOOR, MIN, MAX, 1.0, 1.0)


@pytest.mark.parametrize("kwargs,match", [({"drop_threshold": 0.0}, "drop_threshold"),
                                          ({"drop_threshold": math.nan}, "drop_threshold"),
                                          ({"timeout": -1.0}, "timeout"), ({"timeout": math.inf}, "timeout")])
def test_bad_config_is_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        CliffGuardConfig(**kwargs)


@pytest.mark.parametrize("sensors,match", [([], "at least one"), (["a", "a"], "differ")])
def test_bad_sensor_lists(sensors, match):
    with pytest.raises(ValueError, match=match):
        CliffGuard(CliffGuardConfig(), sensors)
