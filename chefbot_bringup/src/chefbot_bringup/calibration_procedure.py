"""The guided odometry calibration (issue 31): drive test patterns by the robot's own odometry and
compare with a reference of the true motion.

Pure Python, no rospy: the ``calibrate_odometry`` node wraps it around ROS topics (wheel ticks in,
``cmd_vel`` out, the scan as the reference); the tests run it against simulated robots.

The procedure keeps its own dead reckoning (:class:`WheelOdometry`) from the raw wheel ticks with
the parameters as calibrated so far, so each step drives with the previous steps' results loaded
(what :func:`odometry_calibration.calibrate` assumes) without restarting any node:

1. **straight** -- ``distance`` forward, then back: ``ticks_meter`` from odometry / reference
   (:func:`odometry_calibration.straight_line`);
2. **turns** -- ``turns`` full turns on the spot to the left, then as many to the right:
   ``base_width`` from odometry / reference (:func:`odometry_calibration.in_place_turns`);
3. **umbmark** -- a ``side`` x ``side`` square driven clockwise and counter-clockwise ``runs``
   times each; the end errors give the wheel diameter ratio and the effective base
   (:func:`odometry_calibration.umbmark`);
4. **verify** (optional) -- the squares again with the calibrated parameters: UMBmark's E_max
   before and after.

The reference (:class:`Reference`) measures where the robot really went between two standstills:
the laser scan before and after (``scan_reference``), or the user's tape measure.
Every motion is a slow, ramped, closed-loop move on the own odometry; a robot whose wheels do not
move, a reference that fails or any error ends the run with the robot stopped.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

import yaml

from chefbot_bringup import odometry_calibration as oc
from chefbot_bringup.launchpad import wrap_int32
from chefbot_bringup.odometry import integrate_arc


class CalibrationError(RuntimeError):
    """The calibration cannot go on (stalled wheels, no reference, no ticks): the reason for the user."""


class Robot(Protocol):
    """The robot as the procedure sees it (the node: topics and ROS time)."""

    def now(self) -> float:
        """The robot's clock (s; ROS time, sim time in the simulator)."""

    def wait(self, seconds: float) -> None:
        """Let ``seconds`` pass while data keeps arriving."""

    def counts(self) -> tuple[int, int] | None:
        """The latest raw (left, right) wheel ticks, None before any."""

    def drive(self, v: float, w: float) -> None:
        """Command ``v`` m/s forward and ``w`` rad/s to the left."""

    def snapshot(self) -> Any:
        """What the reference compares (the latest scans), or None."""


class Ui(Protocol):
    """The terminal: lines out, blocking questions."""

    def say(self, text: str) -> None:
        """Show one line."""

    def ask(self, text: str) -> str | None:
        """Ask and wait for the reply; None without a user (non-interactive)."""


@dataclass(frozen=True)
class Motion:
    """Where the robot went between two standstills, in the frame of the first (m, m, rad)."""

    x: float
    y: float
    yaw: float

    @property
    def distance(self) -> float:
        """Straight-line distance moved (m)."""
        return math.hypot(self.x, self.y)


class Reference(Protocol):
    """The true motion: ``measure(kind, before, after, guess)``, ``kind`` one of straight / turn / square,
    ``before``/``after`` the robot's snapshots, ``guess`` the odometry's motion (the yaw of N turns is
    ambiguous by 2 pi: the answer nearest the guess). Raises ValueError when it cannot tell."""

    name: str

    def measure(self, kind: str, before: Any, after: Any, guess: Motion) -> Motion:
        """The true motion between the snapshots ``before`` and ``after`` (see the class)."""


class TapeReference:
    """The user measures: asks for the distance, the turned angle or the stop position."""

    name = "tape"

    def __init__(self, ui: Ui) -> None:
        self.ui = ui

    def _number(self, question: str) -> float:
        text = self.ui.ask(question)
        if text is None:
            raise ValueError("no answer (non-interactive): a tape reference needs the user")
        try:
            value = float(text.replace(",", "."))
        except ValueError:
            raise ValueError(f"{text!r} is not a number") from None
        if not math.isfinite(value):
            raise ValueError(f"{text!r} is not a finite number")
        return value

    def measure(self, kind: str, before: Any, after: Any, guess: Motion) -> Motion:
        """Ask for the move of ``kind`` (straight, turn, square); ValueError without a usable answer."""
        if kind == "straight":
            d = self._number(f"how far did the robot move, in m, measured on the floor (odometry says "
                             f"{guess.distance:.3f})?")
            return Motion(math.copysign(abs(d), guess.x), 0.0, guess.yaw)
        if kind == "turn":
            turns = round(guess.yaw / (2 * math.pi))
            extra = self._number(f"the robot turned about {turns} full turns: by how many degrees did it stop "
                                 "past its start heading (+ further in the turning direction, - short of it)?")
            return Motion(0.0, 0.0, turns * 2 * math.pi + math.copysign(math.radians(extra), guess.yaw or 1.0))
        x = self._number("stop position relative to the start mark, along the start heading (forward +), in m?")
        y = self._number("... and across it (to the robot's left +), in m?")
        return Motion(x, y, guess.yaw)


class WheelOdometry:
    """Dead reckoning from raw int32 ticks with per-wheel ticks/m and a base width (``integrate_arc``)."""

    def __init__(self, ticks_meter_left: float, ticks_meter_right: float, base_width: float) -> None:
        self.ticks_meter_left, self.ticks_meter_right, self.base_width = ticks_meter_left, ticks_meter_right, base_width
        self._last: tuple[int, int] | None = None
        self.x = self.y = self.yaw = 0.0

    def reset(self, counts: tuple[int, int]) -> None:
        """Pose 0 at these counts."""
        self._last = counts
        self.x = self.y = self.yaw = 0.0

    def update(self, counts: tuple[int, int]) -> Motion:
        """Advance by the ticks since the last call; the pose since :meth:`reset`."""
        if self._last is None:
            self.reset(counts)
        dl = wrap_int32(counts[0] - self._last[0]) / self.ticks_meter_left
        dr = wrap_int32(counts[1] - self._last[1]) / self.ticks_meter_right
        self._last = counts
        self.x, self.y, self.yaw = integrate_arc(self.x, self.y, self.yaw, dl, dr, self.base_width)
        return self.motion

    @property
    def motion(self) -> Motion:
        """The pose since :meth:`reset`."""
        return Motion(self.x, self.y, self.yaw)


@dataclass(frozen=True)
class CalibrationOptions:
    """The test patterns and how they are driven."""

    distance: float = 1.0            # m: the straight drive (forward, then back)
    turns: int = 2                   # full turns on the spot each way
    side: float = 1.0                # m: the UMBmark square's side (needs side + 0.5 m free around the start)
    runs: int = 1                    # UMBmark runs each way (Borenstein and Feng: 5; each takes a minute)
    verify: bool = True              # drive the squares again with the calibrated parameters
    speed: float = 0.15              # m/s: straight drives
    turn_speed: float = 0.5          # rad/s: turns
    settle: float = 0.7              # s: standstill before each snapshot
    stall_timeout: float = 3.0       # s: commanding motion without a tick changing: the wheels do not turn
    control_period: float = 0.05     # s: between motion commands

    def __post_init__(self) -> None:
        for name in ("distance", "side", "speed", "turn_speed", "settle", "stall_timeout", "control_period"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0, got {v!r}")
        if self.turns < 1 or self.runs < 1:
            raise ValueError(f"turns and runs must be >= 1, got {self.turns}, {self.runs}")
        if self.speed > 0.3 or self.turn_speed > 1.5:
            raise ValueError("speed must be <= 0.3 m/s and turn_speed <= 1.5 rad/s: fast moves slip and spoil "
                             "the calibration")


@dataclass
class CalibrationReport:
    """What was measured and the result."""

    steps: dict[str, Any] = field(default_factory=dict)
    calibration: oc.Calibration | None = None
    e_max_before: float | None = None
    e_max_after: float | None = None
    aborted: str = ""

    def to_dict(self) -> dict:
        """Plain data for the YAML report (numpy numbers as Python ones)."""
        c = self.calibration
        return plain({"aborted": self.aborted, "steps": self.steps,
                "result": None if c is None else {
                    "ticks_meter": round(c.ticks_meter, 1), "ticks_meter_left": round(c.ticks_meter_left, 1),
                    "ticks_meter_right": round(c.ticks_meter_right, 1), "base_width": round(c.base_width, 5),
                    "ticks_meter_before": c.ticks_meter_before, "base_width_before": c.base_width_before},
                "e_max_before": self.e_max_before, "e_max_after": self.e_max_after})


def plain(obj: Any) -> Any:
    """``obj`` with numpy scalars turned into Python numbers, recursively (yaml.safe_dump refuses numpy)."""
    if isinstance(obj, dict):
        return {k: plain(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [plain(v) for v in obj]
    return obj.item() if hasattr(obj, "item") and not isinstance(obj, (str, bytes)) else obj


def e_max(cw: list[tuple[float, float]], ccw: list[tuple[float, float]]) -> float:
    """UMBmark's E_max: the larger distance of the two end-error centroids from the start (m)."""
    def centroid(runs: list[tuple[float, float]]) -> float:
        return math.hypot(sum(p[0] for p in runs) / len(runs), sum(p[1] for p in runs) / len(runs))
    return max(centroid(cw), centroid(ccw))


class OdometryCalibration:
    """Run the calibration on ``robot`` with ``reference``, talking through ``ui``."""

    def __init__(self, robot: Robot, reference: Reference, ui: Ui, ticks_meter: float, base_width: float,
                 options: CalibrationOptions | None = None) -> None:
        self.robot, self.ref, self.ui = robot, reference, ui
        self.opt = options or CalibrationOptions()
        self.ticks_meter0 = oc._positive("ticks_meter", ticks_meter)
        self.base_width0 = oc._positive("base_width", base_width)
        self.odo = WheelOdometry(ticks_meter, ticks_meter, base_width)
        self.report = CalibrationReport()

    # ---------------------------------------------------------------- the whole run
    def run(self) -> CalibrationReport:
        """All steps, then the stop; the report says what was found (or why it ended early)."""
        try:
            self._run()
        except (CalibrationError, ValueError) as exc:
            self.report.aborted = str(exc)
            self.ui.say(f"ABORTED: {exc}")
        finally:                 # also on KeyboardInterrupt, which passes on
            self.stop()
        return self.report

    def stop(self) -> None:
        """Zero velocity, repeated for a moment (one lost message must not leave the robot moving)."""
        for _ in range(3):
            self.robot.drive(0.0, 0.0)
            self.robot.wait(self.opt.control_period)

    def _run(self) -> None:
        o = self.opt
        self.ui.say(f"calibration with the {self.ref.name} reference: ticks_meter {self.ticks_meter0:.1f}, "
                    f"base_width {self.base_width0:.4f} m; keep {o.side + 0.5:.1f} m free around the robot")
        end = self.robot.now() + 10.0
        while self.robot.counts() is None and self.robot.now() < end:
            self.robot.wait(self.opt.control_period)
        if self.robot.counts() is None:
            raise CalibrationError("no wheel ticks (lwheel/rwheel) for 10 s: is robot_standalone.launch running?")
        straight = self.straight_step()
        turn = self.turn_step()
        cw, ccw = self.squares("umbmark")
        self.report.e_max_before = e_max(cw, ccw)
        umb = oc.umbmark(cw, ccw, o.side, self.odo.base_width)
        cal = oc.calibrate(self.ticks_meter0, self.base_width0, straight, turn, umb)
        self.report.calibration = cal
        self.ui.say(f"result: ticks_meter {cal.ticks_meter:.1f} (left {cal.ticks_meter_left:.1f}, right "
                    f"{cal.ticks_meter_right:.1f}), base_width {cal.base_width:.4f} m "
                    f"(before {self.ticks_meter0:.1f}, {self.base_width0:.4f} m)")
        if o.verify:
            self.odo = WheelOdometry(cal.ticks_meter_left, cal.ticks_meter_right, cal.base_width)
            cw2, ccw2 = self.squares("verify")
            self.report.e_max_after = e_max(cw2, ccw2)
            self.ui.say(f"UMBmark E_max: {self.report.e_max_before * 1000:.0f} mm before, "
                        f"{self.report.e_max_after * 1000:.0f} mm after")

    # ---------------------------------------------------------------- measuring one motion
    def _measure(self, kind: str, move: Callable[[], None]) -> tuple[Motion, Motion]:
        """(odometry, reference) of one motion between two standstills."""
        self.robot.wait(self.opt.settle)
        before = self.robot.snapshot()
        start = self.robot.counts()
        if start is None:
            raise CalibrationError("no wheel ticks")
        self.odo.reset(start)
        move()
        self.robot.drive(0.0, 0.0)
        self._wait_still()
        odom = self.odo.update(self.robot.counts())
        after = self.robot.snapshot()
        try:
            true = self.ref.measure(kind, before, after, odom)
        except ValueError as exc:
            raise CalibrationError(f"{kind}: no reference ({self.ref.name}): {exc}") from None
        return odom, true

    def _wait_still(self) -> None:
        """Wait until no tick changed for ``settle`` s (at most 5 s)."""
        last, since, end = self.robot.counts(), self.robot.now(), self.robot.now() + 5.0
        while self.robot.now() < end:
            self.robot.wait(self.opt.control_period)
            c = self.robot.counts()
            if c != last:
                last, since = c, self.robot.now()
            elif self.robot.now() - since >= self.opt.settle:
                return

    # ---------------------------------------------------------------- the moves (closed loop on the own odometry)
    def _loop(self, name: str, command: Callable[[Motion], tuple[float, float] | None], limit: float) -> None:
        """Run ``command(pose) -> (v, w)`` every control period until it returns None."""
        r = self.robot
        end = r.now() + limit
        last_counts, moved_at = self.robot.counts(), r.now()
        while True:
            c = self.robot.counts()
            pose = self.odo.update(c)
            if c != last_counts:
                last_counts, moved_at = c, r.now()
            vw = command(pose)
            if vw is None:
                return
            if r.now() - moved_at > self.opt.stall_timeout:
                raise CalibrationError(f"{name}: commanding motion, but no wheel tick for "
                                       f"{self.opt.stall_timeout:.0f} s (blocked, or the drive chain is not running)")
            if r.now() > end:
                raise CalibrationError(f"{name}: not done after {limit:.0f} s (wheels slipping? obstacle?)")
            r.drive(*vw)
            r.wait(self.opt.control_period)

    def straight(self, distance: float) -> None:
        """Drive ``distance`` m (negative: backwards) along the current heading, holding it."""
        o, sign, t0 = self.opt, math.copysign(1.0, distance), self.robot.now()
        x0, y0, th0 = self.odo.x, self.odo.y, self.odo.yaw

        def command(p: Motion) -> tuple[float, float] | None:
            c, s = math.cos(th0), math.sin(th0)
            along = (p.x - x0) * c + (p.y - y0) * s
            lateral = -(p.x - x0) * s + (p.y - y0) * c
            remaining = abs(distance) - sign * along
            if remaining <= 0.001:
                return None
            ramp = 0.05 + 0.5 * (self.robot.now() - t0)               # accelerate at 0.5 m/s^2
            v = min(o.speed, ramp, max(0.03, 1.0 * remaining))        # slow down over the last 0.15 m
            heading = math.remainder(p.yaw - th0, 2 * math.pi)
            w = -2.0 * heading - 4.0 * lateral * sign                 # hold the line (odometry's line)
            return sign * v, max(-0.3, min(0.3, w))
        self._loop("straight", command, abs(distance) / 0.03 + 10.0)

    def turn(self, angle: float) -> None:
        """Turn ``angle`` rad on the spot (positive: left)."""
        o, sign, t0, th0 = self.opt, math.copysign(1.0, angle), self.robot.now(), self.odo.yaw

        def command(p: Motion) -> tuple[float, float] | None:
            remaining = abs(angle) - sign * (p.yaw - th0)
            if remaining <= 0.002:
                return None
            ramp = 0.1 + 1.5 * (self.robot.now() - t0)
            return 0.0, sign * min(o.turn_speed, ramp, max(0.08, 2.0 * remaining))
        self._loop("turn", command, abs(angle) / 0.08 + 10.0)

    def square(self, side: float, clockwise: bool) -> None:
        """Four times ``side`` m and a quarter turn (right when ``clockwise``)."""
        corner = -math.pi / 2 if clockwise else math.pi / 2
        for _ in range(4):
            self.straight(side)
            self.turn(corner)

    # ---------------------------------------------------------------- the steps
    def straight_step(self) -> float:
        """Step 1: the ticks_meter factor from driving forth and back."""
        d = self.opt.distance
        self.ui.say(f"1/3 straight: {d:.2f} m forward, then back")
        odom_sum = true_sum = 0.0
        rows = []
        for sign in (1.0, -1.0):
            odom, true = self._measure("straight", lambda s=sign: self.straight(s * d))
            odom_sum += odom.distance
            true_sum += true.distance
            rows.append({"odometry_m": round(odom.distance, 4), "reference_m": round(true.distance, 4)})
            self.ui.say(f"    odometry {odom.distance:.4f} m, {self.ref.name} {true.distance:.4f} m")
        factor = oc.straight_line(odom_sum, true_sum)
        self.odo.ticks_meter_left *= factor
        self.odo.ticks_meter_right *= factor
        self.report.steps["straight"] = {"runs": rows, "factor": round(factor, 5)}
        self.ui.say(f"  ticks_meter x {factor:.4f} -> {self.odo.ticks_meter_left:.1f}")
        return factor

    def turn_step(self) -> float:
        """Step 2: the base_width factor from turns both ways."""
        n = self.opt.turns
        self.ui.say(f"2/3 turns: {n} full turn{'s' if n != 1 else ''} to the left, then {n} to the right")
        odom_sum = true_sum = 0.0
        rows = []
        for sign in (1.0, -1.0):
            odom, true = self._measure("turn", lambda s=sign: self.turn(s * n * 2 * math.pi))
            if true.yaw * odom.yaw <= 0:
                raise CalibrationError(f"turn: the reference says {math.degrees(true.yaw):.0f} deg for "
                                       f"{math.degrees(odom.yaw):.0f} deg of odometry")
            odom_sum += abs(odom.yaw)
            true_sum += abs(true.yaw)
            rows.append({"odometry_deg": round(math.degrees(odom.yaw), 2),
                         "reference_deg": round(math.degrees(true.yaw), 2)})
            self.ui.say(f"    odometry {math.degrees(odom.yaw):.1f} deg, "
                        f"{self.ref.name} {math.degrees(true.yaw):.1f} deg")
        factor = oc.in_place_turns(odom_sum, true_sum)
        self.odo.base_width *= factor
        self.report.steps["turns"] = {"runs": rows, "factor": round(factor, 5)}
        self.ui.say(f"  base_width x {factor:.4f} -> {self.odo.base_width:.4f} m")
        return factor

    def squares(self, name: str) -> tuple[list[tuple[float, float]], list[tuple[float, float]]]:
        """UMBmark runs with the current parameters: per run the true stop minus start (start frame) minus
        where odometry believes it stopped (first order: the square's own end tolerance does not count as
        odometry error)."""
        o, base_width = self.opt, self.odo.base_width
        self.ui.say(f"{'3/3 umbmark' if name == 'umbmark' else 'verify'}: a {o.side:.2f} m square clockwise and "
                    f"counter-clockwise, {o.runs} run(s) each (base_width {base_width:.4f} m)")
        out: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
        rows = []
        for _ in range(o.runs):
            for cw in (True, False):
                odom, true = self._measure("square", lambda c=cw: self.square(o.side, c))
                err = (true.x - odom.x, true.y - odom.y)
                out[cw].append(err)
                rows.append({"clockwise": cw, "end_error_m": [round(err[0], 4), round(err[1], 4)]})
                self.ui.say(f"    {'cw ' if cw else 'ccw'}: end error x {err[0] * 1000:+.0f} mm, "
                            f"y {err[1] * 1000:+.0f} mm")
        self.report.steps[name] = {"runs": rows, "side_m": o.side, "base_width": round(base_width, 5)}
        return out[True], out[False]


CALIBRATION_KEYS = ("ticks_meter", "base_width", "ticks_meter_left", "ticks_meter_right")


def merge_calibration(existing: str | None, cal: oc.Calibration) -> str:
    """``cal.to_yaml()`` followed by every other key of the calibration YAML ``existing`` (None: no file),
    e.g. the wheel PID gains ``bringup_check`` wrote; raises ValueError if ``existing`` is not a YAML
    mapping (a corrupt file is not overwritten)."""
    kept = {k: v for k, v in oc.load_calibration_yaml(existing).items() if k not in CALIBRATION_KEYS}
    text = cal.to_yaml()
    if kept:
        text += "# kept from the file before\n" + yaml.safe_dump(kept, sort_keys=False)
    return text
