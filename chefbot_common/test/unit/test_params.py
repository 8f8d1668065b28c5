"""read_config: types, fallbacks, messages that name the parameter."""
import math
from dataclasses import dataclass

import pytest

from chefbot_common.params import ParamError, read_config


@dataclass
class TwistToMotorsConfig:
    """A config shaped like a node's: floats, an int, checks in __post_init__."""

    base_width: float = 0.30
    rate: float = 50.0
    timeout_ticks: int = 18

    def __post_init__(self) -> None:
        for name in ("base_width", "rate"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        if self.timeout_ticks < 1:
            raise ValueError(f"timeout_ticks must be an integer >= 1, got {self.timeout_ticks!r}")


@dataclass
class PidConfig:
    """Gains and a count, like the wheel PID's."""

    kp: float = 1.0
    ticks_meter: float = 1000.0

    def __post_init__(self) -> None:
        if self.kp < 0:
            raise ValueError(f"kp must be >= 0, got {self.kp!r}")

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
