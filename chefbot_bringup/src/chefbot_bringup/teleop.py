"""Keyboard teleoperation logic (core of ``keyboard_teleop``; no terminal, no ROS).

Hold-to-drive: a movement key sets the command, the terminal's key repeat
keeps it alive, and ``key_timeout`` seconds after the last key the command
drops to zero, which is sent once (so another velocity source can take
over).  While a command is active it is re-sent every ``1 / rate`` seconds,
because the terminal's first key repeat comes only after ~0.25-0.66 s, later
than ``twist_to_motors`` would time out.

Both common layouts work (turtlebot / teleop_twist_keyboard and WASD)::

    u    i    o        q/z : all speeds +/- 10 %
    j    k    l        e/c : turn speed +/- 10 %
    m    ,    .        k, s, space : stop now
       w                Ctrl-C : quit
    a  s  d
       x
"""
from __future__ import annotations

import math
from dataclasses import dataclass

# key -> (linear sign, angular sign); angular + = counter-clockwise (left).
MOVE_KEYS: dict[str, tuple[int, int]] = {
    "i": (1, 0), "w": (1, 0),
    ",": (-1, 0), "x": (-1, 0),
    "j": (0, 1), "a": (0, 1),
    "l": (0, -1), "d": (0, -1),
    "u": (1, 1), "o": (1, -1),
    # Reversing: the rear swings toward the side of the key.
    "m": (-1, -1), ".": (-1, 1),
}
STOP_KEYS = frozenset("ks ")
QUIT_KEYS = frozenset("\x03\x04")   # Ctrl-C, Ctrl-D (raw mode delivers them as bytes)
# key -> (linear factor, angular factor)
SCALE_KEYS: dict[str, tuple[float, float]] = {
    "q": (1.1, 1.1), "z": (1 / 1.1, 1 / 1.1),
    "e": (1.0, 1.1), "c": (1.0, 1 / 1.1),
}

HELP = __doc__.split("::", 1)[1].rstrip() if __doc__ else ""


@dataclass(frozen=True)
class TeleopConfig:
    """Keyboard teleop speeds (m/s, rad/s), their limits and the key timeout (s)."""

    linear_speed: float = 0.2    # initial forward speed (m/s)
    angular_speed: float = 1.0   # initial turn rate (rad/s)
    max_linear: float = 0.35     # upper limit for the forward speed (m/s)
    max_angular: float = 2.0     # upper limit for the turn rate (rad/s)
    key_timeout: float = 0.7     # stop this long after the last key (s)
    rate: float = 10.0           # re-send rate of an active command (Hz)

    def __post_init__(self) -> None:
        for name in ("linear_speed", "angular_speed", "max_linear", "max_angular", "key_timeout", "rate"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be a positive finite number, got {v!r}")
        if self.linear_speed > self.max_linear:
            raise ValueError(f"linear_speed ({self.linear_speed}) exceeds max_linear ({self.max_linear})")
        if self.angular_speed > self.max_angular:
            raise ValueError(f"angular_speed ({self.angular_speed}) exceeds max_angular ({self.max_angular})")


class KeyTeleop:
    """Turn key presses and the passage of time into velocity commands."""

    def __init__(self, cfg: TeleopConfig) -> None:
        self.cfg = cfg
        self.linear_speed = cfg.linear_speed
        self.angular_speed = cfg.angular_speed
        self.quit = False
        self._dir = (0, 0)
        self._t_key: float | None = None      # time of the last movement key
        self._t_sent: float | None = None     # time of the last publication
        self._zero_pending = False

    def press(self, key: str, t: float) -> bool:
        """Handle one key at time ``t`` (s); returns True if the key meant something."""
        if key in MOVE_KEYS:
            self._dir = MOVE_KEYS[key]
            self._t_key = t
            self._t_sent = None            # send the new command right away
            return True
        if key in STOP_KEYS:
            self._stop()
            return True
        if key in SCALE_KEYS:
            fl, fa = SCALE_KEYS[key]
            self.linear_speed = min(self.linear_speed * fl, self.cfg.max_linear)
            self.angular_speed = min(self.angular_speed * fa, self.cfg.max_angular)
            self._t_sent = None
            return True
        if key in QUIT_KEYS:
            self._stop()
            self.quit = True
            return True
        return False

    def _stop(self) -> None:
        if self._t_key is not None or self._dir != (0, 0):
            self._zero_pending = True
        self._dir = (0, 0)
        self._t_key = None

    @property
    def velocity(self) -> tuple[float, float]:
        """Current command (m/s, rad/s)."""
        return self._dir[0] * self.linear_speed, self._dir[1] * self.angular_speed

    def poll(self, t: float) -> tuple[float, float] | None:
        """What to publish at time ``t`` (s): a command, a single zero, or None."""
        if self._t_key is not None and t - self._t_key >= self.cfg.key_timeout:
            self._stop()
        if self._zero_pending:
            self._zero_pending = False
            self._t_sent = t
            return 0.0, 0.0
        if self._t_key is None:
            return None
        if self._t_sent is None or t - self._t_sent >= 1.0 / self.cfg.rate - 1e-9:
            self._t_sent = t
            return self.velocity
        return None

    def next_deadline(self, t: float) -> float:
        """Seconds until :meth:`poll` may have something new (for select's timeout)."""
        if self._zero_pending:
            return 0.0
        if self._t_key is None:
            return 1.0
        waits = [self._t_key + self.cfg.key_timeout - t]
        if self._t_sent is not None:
            waits.append(self._t_sent + 1.0 / self.cfg.rate - t)
        return max(0.0, min(waits))

    def status(self) -> str:
        """One status line: the set speeds and the command now."""
        v, w = self.velocity
        return (f"speed {self.linear_speed:.2f} m/s  turn {self.angular_speed:.2f} rad/s  "
                f"now v={v:+.2f} w={w:+.2f}")
