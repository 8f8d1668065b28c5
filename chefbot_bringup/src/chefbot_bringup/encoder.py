"""Encoder tick bookkeeping shared by ``pid_velocity`` and ``diff_tf``.

The LaunchPad reports cumulative tick counters in a fixed integer range
(Int16 in the book's original, Int32 in our firmware).  ``TickUnwrapper``
turns such a wrapping counter into an unbounded integer position, with the
same wrap-detection rule as the book's ``differential_drive`` nodes: a
transition from the top 30 % of the range into the bottom 30 % is a forward
wrap and vice versa.
"""
from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields
from typing import Any

from chefbot_common.params import ParamError, ParamSpec

INT16_RANGE = (-32768, 32767)
INT32_RANGE = (-(2**31), 2**31 - 1)


@dataclass(frozen=True)
class EncoderRange:
    """Counter range of the wheel encoder and the wrap thresholds (ticks)."""

    encoder_min: int = INT32_RANGE[0]
    encoder_max: int = INT32_RANGE[1]
    low_wrap: float | None = None
    high_wrap: float | None = None

    def __post_init__(self) -> None:
        if self.encoder_max <= self.encoder_min:
            raise ValueError(
                f"encoder_max ({self.encoder_max}) must be greater than encoder_min ({self.encoder_min})")
        span = self.span
        # Defaults as in the book: 30 % / 70 % of the range above the minimum.
        if self.low_wrap is None:
            object.__setattr__(self, "low_wrap", self.encoder_min + 0.3 * span)
        if self.high_wrap is None:
            object.__setattr__(self, "high_wrap", self.encoder_min + 0.7 * span)
        if not (self.encoder_min <= self.low_wrap < self.high_wrap <= self.encoder_max):
            raise ValueError(
                f"wheel_low_wrap ({self.low_wrap}) and wheel_high_wrap ({self.high_wrap}) must satisfy "
                f"encoder_min <= wheel_low_wrap < wheel_high_wrap <= encoder_max")

    @property
    def span(self) -> int:
        """Number of distinct counter values (ticks)."""
        # The book uses max - min with max = 32768; we accept either the
        # inclusive maximum (32767) or the book's exclusive one (32768).
        inclusive = self.encoder_max - self.encoder_min + 1
        return inclusive if inclusive % 2 == 0 else inclusive - 1


class TickUnwrapper:
    """Turn a wrapping tick counter into an unbounded integer position (ticks)."""

    def __init__(self, rng: EncoderRange) -> None:
        self.rng = rng
        self._last_raw: int | None = None
        self._offset = 0

    @property
    def initialised(self) -> bool:
        """True once a first reading set the baseline."""
        return self._last_raw is not None

    def reset(self) -> None:
        """Forget history; the next reading becomes the new baseline."""
        self._last_raw = None
        self._offset = 0

    def update(self, raw: int) -> int:
        """Feed one raw counter reading; return the unwrapped position (ticks)."""
        raw = int(raw)
        rng = self.rng
        if self._last_raw is not None:
            if raw < rng.low_wrap and self._last_raw > rng.high_wrap:
                self._offset += rng.span
            elif raw > rng.high_wrap and self._last_raw < rng.low_wrap:
                self._offset -= rng.span
        self._last_raw = raw
        return raw + self._offset


@dataclass(frozen=True)
class EncoderParams:
    """The encoder parameters of ``pid_velocity`` and ``diff_tf`` (global as in the book, private as fallback)."""

    encoder_min: int | float = INT32_RANGE[0]   # ticks: lowest counter value
                                                #   (pid_velocity with wheel_type Int16: -32768)
    encoder_max: int | float = INT32_RANGE[1]   # ticks: highest counter value
                                                #   (pid_velocity with wheel_type Int16: 32767)
    wheel_low_wrap: float | None = None         # ticks: a jump from above wheel_high_wrap to below this is a
                                                #   forward wrap (unset: 30 % of the range above encoder_min)
    wheel_high_wrap: float | None = None        # ticks: see wheel_low_wrap (unset: 70 % of the range)

    def __post_init__(self) -> None:
        for name in ("encoder_min", "encoder_max", "wheel_low_wrap", "wheel_high_wrap"):
            v = getattr(self, name)
            optional = name.startswith("wheel_")
            if not (optional and v is None) and (isinstance(v, bool) or not isinstance(v, (int, float))):
                raise ValueError(f"{name} must be a number, got {v!r}")


ENCODER_PARAMS = ParamSpec(EncoderParams, {f.name: (f.name, "~" + f.name) for f in fields(EncoderParams)})


def read_encoder_range(get: Callable[[str, Any], Any], default: tuple[int, int] = INT32_RANGE) -> EncoderRange:
    """encoder_min/max and the wrap thresholds from parameters (:data:`ENCODER_PARAMS`): global as in the
    book, private as fallback; ``default``: the counter range when encoder_min/max are not set.

    ``get`` is ``rospy.get_param``; wrong types or values raise ParamError naming the parameter.
    """
    p = ENCODER_PARAMS.read(get, encoder_min=default[0], encoder_max=default[1])
    try:
        return EncoderRange(int(p.encoder_min), int(p.encoder_max), p.wheel_low_wrap, p.wheel_high_wrap)
    except ValueError as exc:
        raise ParamError(str(exc)) from exc
