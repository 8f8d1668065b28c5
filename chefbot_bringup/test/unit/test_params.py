"""read_config: types, fallbacks, messages that name the parameter."""
import pytest

from chefbot_bringup.params import ParamError, read_config
from chefbot_bringup.twist_to_motors import TwistToMotorsConfig
from chefbot_bringup.wheel_pid import PidConfig

NAMES = {"base_width": ("~base_width", "base_width"), "rate": "~rate", "timeout_ticks": "~timeout_ticks"}


def getter(d):
    return lambda name, default: d.get(name, default)


def test_private_beats_global_and_defaults_fill_in():
    cfg = read_config(TwistToMotorsConfig, getter({"~base_width": 0.3, "base_width": 0.1}), NAMES)
    assert cfg.base_width == 0.3 and cfg.rate == 50.0
    cfg = read_config(TwistToMotorsConfig, getter({"base_width": 0.25}), NAMES)
    assert cfg.base_width == 0.25


@pytest.mark.parametrize("params,match", [
    ({"~rate": -1.0}, "~rate"),
    ({"~rate": "fast"}, "~rate"),
    ({"~timeout_ticks": 2.5}, "~timeout_ticks"),
    ({"base_width": 0.0}, "parameter base_width"),
    ({"~rate": True}, "~rate"),
])
def test_errors_name_the_parameter(params, match):
    with pytest.raises(ParamError, match=match):
        read_config(TwistToMotorsConfig, getter(params), NAMES)


def test_pid_names():
    cfg = read_config(PidConfig, getter({"~Kp": 10, "ticks_meter": 29708}),
                      {"kp": "~Kp", "ticks_meter": ("ticks_meter", "~ticks_meter")})
    assert cfg.kp == 10.0 and cfg.ticks_meter == 29708.0
    with pytest.raises(ParamError, match="~Kp"):
        read_config(PidConfig, getter({"~Kp": -1}), {"kp": "~Kp"})
