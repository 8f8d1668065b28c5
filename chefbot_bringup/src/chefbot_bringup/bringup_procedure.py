"""The guided bring-up check (issue 31): drive the board step by step and judge what it did.

Pure Python, no rospy: the ``bringup_check`` node wraps it around a serial port and the
terminal; the tests run it against the board emulator (our firmware core) on a real
pseudo-terminal, in simulated time. The diagnosis itself is :mod:`bringup_check`.

The check owns the board's serial port (launchpad_node must not run): it sends the
protocol's ``s <left> <right>`` and ``r`` lines itself (firmware/PROTOCOL.md) and reads the
raw status lines, so it sees the hello line, the line rates and the raw encoder counts.

Steps (each prints one verdict line per finding, with the fix):

1. **board** -- reset the board (``r``), wait for the ``v`` hello, listen ``board_seconds``:
   hello/protocol/decoding, status line rate, battery, IMU, sonar
   (:func:`bringup_check.board_verdicts`). Without status lines nothing else can run.
2. **motors** -- robot on blocks: each motor alone, forward then backward at ``duty`` for
   ``run_seconds``, counting until the wheels stand still again; optionally each wheel turned
   one turn forward by hand when asked (``hand_turns``)
   (:func:`bringup_check.diagnose_motors`).
3. **pid** -- only when the wiring is right: both wheels' speed loops (our
   :class:`wheel_pid.WheelController` with the configured gains, ticked on every encoder line
   as ``pid_velocity``) step to ``pid_target`` m/s (:func:`bringup_check.step_response_verdict`).

Safety: every wait keeps sending a command every ``command_period`` (the firmware's watchdog
stops the motors 0.5 s after the last valid ``s`` line), and :meth:`BringupCheck.run` ends with
a stop that waits for the board's own ``s`` echo to read 0/0 -- also after an error or an
interrupt (``KeyboardInterrupt`` passes through after the stop).
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field, replace
from typing import Protocol

import numpy as np
import yaml

from chefbot_bringup import bringup_check as bc
from chefbot_bringup import launchpad_protocol as proto
from chefbot_bringup import pid_autotune
from chefbot_bringup.launchpad import LineAssembler, wrap_int32
from chefbot_bringup.odometry_calibration import load_calibration_yaml
from chefbot_bringup.wheel_pid import PidConfig, WheelController, WheelVelocityEstimator

COMMAND_MAX = proto.COMMAND_MAX
# The speed loops are closed on the PC: a sample answered late adds dead time the gains never see on an
# idle PC, and the step can look oscillating or slow.  A step that fails while its slowest answer came
# more than HOST_LAG_MAX later than its quickest is run again, PID_STEP_TRIES times in all.
HOST_LAG_MAX = 0.1     # s (three 30 Hz cycles)
PID_STEP_TRIES = 3


class LinkError(RuntimeError):
    """The serial link failed (port gone, write refused)."""


class Link(Protocol):
    """The board's serial port and a clock (seconds)."""

    def now(self) -> float:
        """The link's clock (s)."""

    def write(self, data: bytes) -> None:
        """Send bytes to the board."""

    def read(self, timeout: float) -> bytes:
        """What arrived within ``timeout`` s (may be empty)."""


class Ui(Protocol):
    """The terminal: ``say`` prints a line; ``ask`` shows a question whose reply ``answer``
    returns once the user gave it (None until then)."""

    def say(self, text: str) -> None:
        """Show one line."""

    def ask(self, text: str) -> None:
        """Show a question; its reply comes through :meth:`answer`."""

    def answer(self) -> str | None:
        """The reply to the last question once given, else None."""


@dataclass(frozen=True)
class CheckOptions:
    """What the check does and how long it takes (defaults: about 25 s without questions)."""

    board_seconds: float = 3.0      # s: listening in the board step (line rates, battery, IMU, sonar)
    hello_timeout: float = 3.0      # s: wait for the board's `v` hello line after the reset
    duty: float = 0.3               # fraction: of full command in the motor runs (0.05..0.6; robot on blocks)
    run_seconds: float = 1.5        # s: each motor run is commanded this long
    still_seconds: float = 0.3      # s: a wheel stands still when its count did not change this long
    still_timeout: float = 3.0      # s: longest wait for the wheels to stop after a run
    hand_turns: bool = True         # ask the user to turn each wheel one turn forward by hand (interactive only)
    sonar_hand: bool = False        # ask the user to hold a hand in front of the sonar (interactive only)
    pid_step: bool = True           # step both wheels' speed loops (only when the wiring is right)
    pid_target: float = 0.2         # m/s: the speed loops' step target
    pid_seconds: float = 2.0        # s: length of the step record
    autotune: bool = False          # fit each wheel's forward run, propose PI gains, step the loops with them
    answer_timeout: float = 300.0   # s: wait for the user's Enter, then the step is skipped
    command_period: float = 0.05    # s: between commands to the board (its watchdog stops the motors at 0.5 s)

    def __post_init__(self) -> None:
        for name in ("board_seconds", "hello_timeout", "run_seconds", "still_seconds", "still_timeout",
                     "pid_seconds", "answer_timeout", "command_period"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v > 0):
                raise ValueError(f"{name} must be > 0 s, got {v!r}")
        if not (math.isfinite(self.duty) and 0.05 <= self.duty <= 0.6):
            raise ValueError(f"duty must be in [0.05, 0.6] (robot on blocks, low duty), got {self.duty!r}")
        if self.command_period >= 0.4:
            raise ValueError(f"command_period must be < 0.4 s (the firmware's watchdog stops at 0.5 s), "
                             f"got {self.command_period!r}")
        if not (math.isfinite(self.pid_target) and 0 < self.pid_target):
            raise ValueError(f"pid_target must be > 0 m/s, got {self.pid_target!r}")


@dataclass
class Sample:
    """One encoder line: arrival time (s, the link's clock), the raw int32 counts, and the board's
    clock of its status cycle (s, from the `t` line before it; None without one)."""

    t: float
    left: int
    right: int
    board_t: float | None = None

    @property
    def clock(self) -> float:
        """The board's cycle clock when known, else the arrival: arrival times carry the link's jitter
        (USB, a loaded PC), which a speed estimate turns into a ripple of several per cent."""
        return self.t if self.board_t is None else self.board_t

    def count(self, side: str) -> int:
        """The counter of wheel ``side`` ("left" / "right")."""
        return self.left if side == "left" else self.right


@dataclass
class StepReport:
    """One step's verdicts (and what it measured, for the report file)."""

    name: str
    verdicts: list[bc.Verdict] = field(default_factory=list)
    data: dict = field(default_factory=dict)
    records: dict = field(default_factory=dict, repr=False)   # a pid step's (t, speed) per wheel; not reported

    @property
    def ok(self) -> bool:
        """True when the step has verdicts and all are ok."""
        return bool(self.verdicts) and all(v.ok for v in self.verdicts)


@dataclass
class Report:
    """The whole check: its steps, whether the motors were seen stopped at the end."""

    steps: list[StepReport] = field(default_factory=list)
    motors_stopped: bool | None = None     # the board's `s` echo read 0/0 after the final stop (None: unknown)
    aborted: str = ""                      # why the check ended early ("" = it ran to the end)

    @property
    def ok(self) -> bool:
        """True when the check ran to the end and every step is ok."""
        return not self.aborted and bool(self.steps) and all(s.ok for s in self.steps)

    def codes(self) -> list[str]:
        """The failing verdicts' codes, in order."""
        return [v.code for s in self.steps for v in s.verdicts if not v.ok]

    def to_dict(self) -> dict:
        """Plain data for the YAML report."""
        return {
            "ok": self.ok,
            "aborted": self.aborted,
            "motors_stopped": self.motors_stopped,
            "faults": self.codes(),
            "steps": [{"name": s.name, "ok": s.ok,
                       "verdicts": [{"ok": v.ok, "code": v.code, "side": v.side, "message": v.message,
                                     "fix": v.fix} for v in s.verdicts],
                       "data": s.data} for s in self.steps],
        }


class Board:
    """The board seen through the link: parses lines, keeps the latest of each, sends commands."""

    def __init__(self, link: Link, command_period: float = 0.05) -> None:
        self.link = link
        self.command_period = command_period
        self.assembler = LineAssembler()
        self.counts: Sample | None = None       # latest `e` line
        self.hello: tuple[str, ...] | None = None
        self.echo: proto.SpeedEcho | None = None
        self.battery: float | None = None
        self.tally: dict[str, list[float]] = {"e": [], "i": [], "u": []}   # arrival times per kind
        self.sonar: list[float] = []            # `u` readings (cm)
        self.bad_lines = 0
        self.board_clock: float | None = None   # s, the last `t` line's micros, unwrapped
        self._micros: int | None = None
        self.on_sample: Callable[[Sample], None] | None = None
        self._command: tuple[float, float] | None = None
        self._last_sent = -math.inf

    def send(self, data: bytes) -> None:
        """Write ``data``; LinkError if the port refuses."""
        try:
            self.link.write(data)
        except (OSError, ValueError) as exc:       # pyserial's SerialException is an OSError
            raise LinkError(f"cannot write to the board: {exc}") from exc

    def command(self, left: float, right: float) -> None:
        """Set the motor command (cmd units) sent from now on, every command_period; sent at once."""
        self._command = (left, right)
        self._last_sent = -math.inf
        self._keep_alive()

    def _keep_alive(self) -> None:
        if self._command is not None and self.link.now() - self._last_sent >= self.command_period:
            self.send(proto.format_command(*self._command))
            self._last_sent = self.link.now()

    def reset(self) -> None:
        """``r``: the board restarts (counts 0, a new hello line); the command goes back to 0."""
        self.hello = None
        self.counts = None
        self._micros = None          # the board's clock restarts; board_clock keeps increasing
        self._command = (0.0, 0.0)
        self.send(proto.format_reset())
        self._last_sent = self.link.now()

    def pump(self, seconds: float, until: Callable[[], bool] | None = None) -> bool:
        """Read and parse for ``seconds`` (keeping the command alive); True if ``until()`` became true."""
        end = self.link.now() + seconds
        while True:
            if until is not None and until():
                return True
            now = self.link.now()
            if now >= end:
                return False
            self._keep_alive()
            try:
                data = self.link.read(min(end - now, self.command_period / 2))
            except (OSError, ValueError) as exc:
                raise LinkError(f"cannot read from the board: {exc}") from exc
            if data:
                self._parse(data)

    def _parse(self, data: bytes) -> None:
        t = self.link.now()
        for raw in self.assembler.feed(data):
            if isinstance(raw, proto.LineError):
                self.bad_lines += 1
                continue
            try:
                msg, _crc = proto.parse_line(raw)
            except proto.LineError:
                self.bad_lines += 1
                continue
            if isinstance(msg, proto.TimeStamp):
                step = 0 if self._micros is None else (msg.micros - self._micros) % 2**32
                self._micros = msg.micros
                self.board_clock = (self.board_clock or 0.0) + step * 1e-6
            elif isinstance(msg, proto.Encoders):
                self.counts = Sample(t, msg.left, msg.right, self.board_clock)
                self.tally["e"].append(t)
                if self.on_sample is not None:
                    self.on_sample(self.counts)
            elif isinstance(msg, proto.Hello):
                self.hello = msg.fields
            elif isinstance(msg, proto.SpeedEcho):
                self.echo = msg
            elif isinstance(msg, proto.Battery):
                self.battery = msg.volts
            elif isinstance(msg, proto.Quaternion):
                self.tally["i"].append(t)
            elif isinstance(msg, proto.Ultrasonic):
                self.tally["u"].append(t)
                self.sonar.append(msg.cm)

    def rate(self, kind: str, since: float) -> float:
        """Lines of ``kind`` per second since ``since`` (s)."""
        span = self.link.now() - since
        return sum(1 for t in self.tally[kind] if t >= since) / span if span > 0 else 0.0

    def stop(self, wait: float = 1.0) -> bool:
        """Command 0/0 and wait up to ``wait`` s for the board's echo to show it; True if seen."""
        self.command(0.0, 0.0)
        self.echo = None

        def stopped() -> bool:
            e = self.echo
            return e is not None and abs(e.left) < 0.5 and abs(e.right) < 0.5
        return self.pump(wait, stopped)


@dataclass(frozen=True)
class OpenLoop:
    """One motor run's record while commanded: the samples (the one before the command first), the
    command's delay after that first sample, the command."""

    delay: float              # s from the first sample's arrival to the command going out
    command: float            # cmd units
    samples: list[Sample]     # the sample before the command and every encoder line while commanded

    def speed_record(self, side: str, pid: PidConfig) -> tuple[list[float], list[float]]:
        """(t from the command, wheel speed) through the loop's own estimator, on the board's clock."""
        est = WheelVelocityEstimator(pid)
        first = self.samples[0]
        t_cmd = first.clock + self.delay
        rest_history(est.add_reading, first.count(side), first.clock, pid)
        t: list[float] = []
        v: list[float] = []
        for smp in self.samples[1:]:
            c = smp.clock
            est.add_reading(smp.count(side), c)
            if c >= t_cmd and (not t or c - t_cmd > t[-1]):
                t.append(c - t_cmd)
                v.append(est.velocity(c))
        if t and t[0] > 0:
            t.insert(0, 0.0)
            v.insert(0, 0.0)
        return t, v


def rest_history(add_reading: Callable[[int, float], None], count: int, t: float, pid: PidConfig) -> None:
    """Feed a speed estimator the readings of a wheel at rest up to ``t``: a full rolling window, as
    ``pid_velocity``'s estimator has when a step comes after a pause (its lag at the step's start)."""
    for k in range(int(pid.rolling_pts), -1, -1):
        add_reading(count, t - k / pid.rate)


def count_delta(a: int, b: int) -> int:
    """b - a of two int32 counters, across a wrap."""
    return wrap_int32(b - a)


class BringupCheck:
    """Run the steps of the check against ``link``, talking to the user through ``ui``."""

    def __init__(self, link: Link, ui: Ui, options: CheckOptions | None = None,
                 expect: bc.Expectations | None = None, pid: PidConfig | None = None) -> None:
        self.opt = options or CheckOptions()
        self.ui = ui
        self.expect = expect or bc.Expectations()
        self.pid = pid or PidConfig(ticks_meter=self.expect.ticks_meter, max_speed=self.expect.max_wheel_speed)
        self.board = Board(link, self.opt.command_period)
        self.report = Report()
        self.open_loop: dict[tuple[str, bool], OpenLoop] = {}   # (side, forward) -> the run's record
        self.proposed: pid_autotune.Gains | None = None         # gains the autotune found better, if any

    # ---------------------------------------------------------------- the whole check
    def run(self) -> Report:
        """All steps, then the stop; the report says what was found."""
        try:
            self._run_steps()
        except LinkError as exc:
            self.report.aborted = str(exc)
            self.ui.say(f"ABORTED: {exc}. The firmware's watchdog stops the motors 0.5 s after the last command.")
        finally:            # also on KeyboardInterrupt, which then passes on
            try:
                self.report.motors_stopped = self.board.stop()
            except LinkError:
                self.report.motors_stopped = None
            if self.report.motors_stopped:
                self.ui.say("motors stopped (the board confirms 0/0)")
            elif self.report.motors_stopped is False:
                self.ui.say("the board did not confirm the stop; its watchdog stops the motors 0.5 s after the "
                            "last command")
        return self.report

    def _run_steps(self) -> None:
        board = self.board_step()
        if any(v.code == "no_status" for v in board.verdicts):
            self.report.aborted = "no status lines from the board: the motor steps need its encoder counts"
            self.ui.say(f"ABORTED: {self.report.aborted}")
            return
        motors = self.motor_step()
        if not self.opt.pid_step:
            return
        if motors.ok:
            current = self.pid_step()
            if self.opt.autotune:
                self.autotune_step(current)
        else:
            self.ui.say("pid: skipped until the wiring faults above are fixed (a reversed wheel would run away)")

    def _show(self, step: StepReport) -> StepReport:
        for v in step.verdicts:
            self.ui.say(f"  [{'ok' if v.ok else 'FAIL'}] {v.line()}")
        self.report.steps.append(step)
        return step

    def _wait_answer(self, question: str) -> str | None:
        """Ask and keep the board link alive until the user answers; None after answer_timeout."""
        self.ui.ask(question)
        got: list[str] = []

        def answered() -> bool:
            a = self.ui.answer()
            if a is not None:
                got.append(a)
            return bool(got)
        self.board.pump(self.opt.answer_timeout, answered)
        return got[0] if got else None

    # ---------------------------------------------------------------- 1. the board
    def board_step(self) -> StepReport:
        """Step 1: reset the board, wait for its hello, judge its lines (board_verdicts)."""
        b = self.board
        self.ui.say("1/3 board: resetting it and listening ...")
        b.reset()
        b.pump(self.opt.hello_timeout, lambda: b.hello is not None)
        t0 = b.link.now()
        b.command(0.0, 0.0)
        b.pump(self.opt.board_seconds)
        no_echo = None
        if self.opt.sonar_hand and b.tally["u"]:
            if self._wait_answer("hold a hand 20-50 cm in front of the sonar and press Enter") is not None:
                n0 = len(b.sonar)
                b.pump(1.0)
                seen = b.sonar[n0:]
                no_echo = sum(1 for cm in seen if cm <= 0) / len(seen) if seen else None
        rep = bc.BoardReport(hello=b.hello, status_rate_hz=b.rate("e", t0), battery_volts=b.battery,
                             imu_rate_hz=b.rate("i", t0), sonar_rate_hz=b.rate("u", t0),
                             sonar_no_echo_fraction=no_echo)
        step = StepReport("board", bc.board_verdicts(rep, self.expect),
                          {"hello": list(rep.hello) if rep.hello else None,
                           "status_rate_hz": round(rep.status_rate_hz, 2),
                           "battery_volts": rep.battery_volts, "imu_rate_hz": round(rep.imu_rate_hz, 2),
                           "sonar_rate_hz": round(rep.sonar_rate_hz, 2), "bad_lines": b.bad_lines})
        return self._show(step)

    # ---------------------------------------------------------------- 2. the motors
    def _wait_still(self) -> None:
        """Command 0 and wait until neither count changed for still_seconds (at most still_timeout)."""
        b = self.board
        b.command(0.0, 0.0)
        state = {"since": b.link.now(), "last": b.counts}

        def still() -> bool:
            c = b.counts
            last = state["last"]
            if c is not None and (last is None or (c.left, c.right) != (last.left, last.right)):
                state["since"], state["last"] = c.t, c
            return b.link.now() - state["since"] >= self.opt.still_seconds
        b.pump(self.opt.still_timeout, still)

    def motor_run(self, side: str, duty: float) -> bc.MotorRun:
        """One motor alone at ``duty`` for run_seconds, counted until the wheels stand still."""
        b = self.board
        self._wait_still()
        start = b.counts
        if start is None:
            raise LinkError("no encoder line from the board")
        samples: list[Sample] = [start]
        b.on_sample = samples.append
        value = duty * COMMAND_MAX
        t0 = b.link.now()
        b.command(value if side == "left" else 0.0, value if side == "right" else 0.0)
        b.pump(self.opt.run_seconds)
        seconds = b.link.now() - t0
        n_commanded = len(samples)
        self._wait_still()
        b.on_sample = None
        end = b.counts
        run = bc.MotorRun(side, duty, seconds, count_delta(start.left, end.left), count_delta(start.right, end.right))
        # the commanded part, for the autotune's model fit; the command went out t0 - start.t after the start sample
        self.open_loop[(side, duty > 0)] = OpenLoop(t0 - start.t, value, samples[:n_commanded])
        return run

    def hand_turn(self, side: str) -> bc.HandTurn | None:
        """Ask the user to turn wheel ``side`` one turn forward; None if unanswered."""
        b = self.board
        self._wait_still()
        start = b.counts
        answer = self._wait_answer(f"turn the {side.upper()} wheel ONE full turn FORWARD by hand (the way it "
                                   "rolls when the robot drives ahead), then press Enter")
        if answer is None or start is None or b.counts is None:
            self.ui.say(f"  no answer: the {side} hand turn is skipped")
            return None
        b.pump(0.2)
        end = b.counts
        return bc.HandTurn(side, count_delta(start.left, end.left), count_delta(start.right, end.right))

    def motor_step(self) -> StepReport:
        """Step 2: each motor alone forward and backward, the hand turns, the wiring diagnosis."""
        self.ui.say(f"2/3 motors: robot on blocks, wheels free; each motor alone at {self.opt.duty:.0%} duty, "
                    f"forward then backward, {self.opt.run_seconds:.1f} s each")
        runs: list[bc.MotorRun] = []
        for side in bc.SIDES:
            for sign, word in ((1, "forward"), (-1, "backward")):
                self.ui.say(f"  {side} motor {word} ...")
                run = self.motor_run(side, sign * self.opt.duty)
                runs.append(run)
                self.ui.say(f"    counts: left {run.left_counts:+d}, right {run.right_counts:+d}")
        turns = []
        if self.opt.hand_turns:
            for side in bc.SIDES:
                t = self.hand_turn(side)
                if t is not None:
                    self.ui.say(f"    counts: left {t.left_counts:+d}, right {t.right_counts:+d}")
                    turns.append(t)
        verdicts = bc.diagnose_motors(runs, turns, self.expect)
        data = {"runs": [{"side": r.side_commanded, "duty": r.duty, "seconds": round(r.seconds, 3),
                          "left_counts": r.left_counts, "right_counts": r.right_counts} for r in runs],
                "hand_turns": [{"side": t.side, "left_counts": t.left_counts, "right_counts": t.right_counts}
                               for t in turns]}
        return self._show(StepReport("motors", verdicts, data))

    # ---------------------------------------------------------------- 3. the speed loops
    def step_record(self, pid: PidConfig) -> tuple[dict[str, tuple[list[float], list[float]]], float]:
        """Both wheels' loops (``pid``) step to pid_target for pid_seconds; per wheel (t, speed), and how
        much later than the quickest one the slowest sample was answered (s: the PC's lag, see
        :data:`HOST_LAG_MAX`)."""
        b = self.board
        self._wait_still()
        ctrl = {s: WheelController(pid) for s in bc.SIDES}
        rec: dict[str, tuple[list[float], list[float]]] = {s: ([], []) for s in bc.SIDES}
        t0 = [b.link.now()]      # the step's start on the samples' clock (set from the last sample below)
        cmd = {"left": 0.0, "right": 0.0}
        answered: list[float] = []   # link clock when each sample's command goes out, minus the sample's clock

        def on_sample(smp: Sample) -> None:
            t = smp.clock
            if rec["left"][0] and t - t0[0] <= rec["left"][0][-1]:
                return                               # not a new cycle
            answered.append(b.link.now() - t)
            for s in bc.SIDES:
                c = ctrl[s]
                c.add_reading(smp.count(s), t)
                c.set_target(self.opt.pid_target)
                out = c.tick(t)
                if out.motor_cmd is not None:
                    cmd[s] = out.motor_cmd
                rec[s][0].append(t - t0[0])
                rec[s][1].append(out.wheel_vel)
            b.command(cmd["left"], cmd["right"])

        if b.counts is not None:
            t0[0] = b.counts.clock
            for s in bc.SIDES:
                rest_history(ctrl[s].add_reading, b.counts.count(s), t0[0], pid)
        b.on_sample = on_sample
        try:
            b.pump(self.opt.pid_seconds)
        finally:
            b.on_sample = None
            self._wait_still()
        return rec, (max(answered) - min(answered)) if answered else 0.0

    def pid_step(self, pid: PidConfig | None = None, name: str = "pid") -> StepReport:
        """Step 3: both speed loops (``pid``, default the configured gains) step to pid_target; their verdicts."""
        pid = pid or self.pid
        title = "3/3 pid" if name == "pid" else "autotune"
        self.ui.say(f"{title}: both wheels' speed loops (Kp {pid.kp:.0f}, Ki {pid.ki:.0f}, Kd {pid.kd:.0f}) step to "
                    f"{self.opt.pid_target:.2f} m/s for {self.opt.pid_seconds:.1f} s")
        for attempt in range(1, PID_STEP_TRIES + 1):
            rec, lag = self.step_record(pid)
            verdicts: list[bc.Verdict] = []
            data: dict = {"gains": {"Kp": pid.kp, "Ki": pid.ki, "Kd": pid.kd}, "target": self.opt.pid_target,
                          "host_lag_ms": round(lag * 1000.0, 1)}
            for s in bc.SIDES:
                t, v = rec[s]
                if len(t) < 5:
                    verdicts.append(bc.Verdict(False, "pid_no_data", f"{s} wheel: too few encoder lines during the "
                                               "step", "the board stopped talking: look at the link", s))
                    continue
                res = bc.step_response_verdict(t, self.opt.pid_target, v)
                verdicts += [replace(x, message=f"{s} wheel: {x.message}", side=s) for x in res.verdicts]
                data[s] = {"rise_time": None if res.rise_time is None else round(res.rise_time, 3),
                           "overshoot_pct": round(res.overshoot_pct, 1),
                           "steady_state_error": round(res.steady_state_error, 4), "oscillations": res.oscillations}
            if lag <= HOST_LAG_MAX or all(x.ok for x in verdicts):
                break
            if attempt < PID_STEP_TRIES:
                self.ui.say(f"  this PC answered the board up to {lag * 1000:.0f} ms late during the step (more than "
                            f"{HOST_LAG_MAX * 1000:.0f} ms): the response says nothing about the gains; again "
                            f"({attempt + 1}/{PID_STEP_TRIES})")
            else:
                verdicts.append(bc.Verdict(
                    False, "pid_host_busy", f"this PC answered the board up to {lag * 1000:.0f} ms late in each of "
                    f"{PID_STEP_TRIES} steps (more than {HOST_LAG_MAX * 1000:.0f} ms): the speed loops' verdicts "
                    "above may be the PC's, not the gains'", "close what keeps the PC busy (a build, a simulator) "
                    "and run the check again"))
        return self._show(StepReport(name, verdicts, data, rec))

    # ---------------------------------------------------------------- 3b. autotune (optional)
    def autotune_step(self, current: StepReport) -> StepReport:
        """Fit each wheel's forward run (FOPDT), propose PI gains for the mean model, step the loops
        with them and compare with the current gains' step, ``current`` (pid_autotune)."""
        self.ui.say("autotune: fitting each wheel's forward run, proposing PI gains")
        models: dict[str, pid_autotune.Fopdt] = {}
        verdicts: list[bc.Verdict] = []
        for s in bc.SIDES:
            rec = self.open_loop.get((s, True))
            try:
                if rec is None:
                    raise ValueError("no forward run recorded")
                t, v = rec.speed_record(s, self.pid)
                models[s] = pid_autotune.fit_fopdt(t, v, rec.command)
            except ValueError as exc:
                verdicts.append(bc.Verdict(False, "autotune_fit", f"{s} wheel: no model from its run: {exc}",
                                           "keep the current gains; look at the run's counts", s))
        data: dict = {"models": {s: {"gain_per_full_command": round(m.gain * COMMAND_MAX, 4),
                                     "tau": round(m.tau, 4), "dead_time": round(m.dead_time, 4),
                                     "rmse": round(m.rmse, 5)} for s, m in models.items()}}
        if len(models) < 2:
            return self._show(StepReport("autotune", verdicts, data))
        mean = pid_autotune.Fopdt(*(sum(getattr(m, f) for m in models.values()) / 2
                                    for f in ("gain", "tau", "dead_time", "rmse")))
        gains = pid_autotune.propose_gains(mean, self.pid, self.opt.pid_target)
        data["proposed"] = {k: round(v, 1) for k, v in gains.to_params().items()}
        tuned = self.pid_step(replace(self.pid, kp=gains.kp, ki=gains.ki, kd=gains.kd), name="pid_autotuned")
        better = []
        for s in bc.SIDES:
            (tc, vc), (tn, vn) = current.records[s], tuned.records[s]
            if len(tc) < 5 or len(tn) < 5:
                continue
            cmp = pid_autotune.compare_steps(tc, self.opt.pid_target, vc, np.interp(tc, tn, vn))
            better.append(cmp.better and tuned.ok)
            data[s] = {"iae_current": round(cmp.current.iae, 4), "iae_proposed": round(cmp.proposed.iae, 4),
                       "overshoot_current_pct": round(cmp.current.overshoot_pct, 1),
                       "overshoot_proposed_pct": round(cmp.proposed.overshoot_pct, 1)}
        g = ", ".join(f"{k} {v:.0f}" for k, v in gains.to_params().items() if k != "Kd")
        if len(better) == 2 and all(better):
            self.proposed = gains
            verdicts.append(bc.Verdict(True, "autotune_better",
                                       f"autotuned gains ({g}) step better than the current ones on both wheels "
                                       f"(IAE {data['left']['iae_current']:.3f} -> {data['left']['iae_proposed']:.3f} "
                                       f"left, {data['right']['iae_current']:.3f} -> "
                                       f"{data['right']['iae_proposed']:.3f} right)",
                                       "put them in lwheel_pid/rwheel_pid (write_gains, or the calibration file)"))
        else:
            verdicts.append(bc.Verdict(True, "autotune_keep",
                                       f"autotuned gains ({g}) are not better on both wheels: keep the current ones"))
        data["better"] = self.proposed is not None
        return self._show(StepReport("autotune", verdicts, data))


def merge_gains(existing: str | None, gains: pid_autotune.Gains) -> str:
    """The calibration YAML ``existing`` (None: no file yet) with ``lwheel_pid``/``rwheel_pid`` Kp, Ki, Kd
    set to ``gains``; every other key kept. Raises ValueError if ``existing`` is not a YAML mapping
    (a corrupt file is not overwritten)."""
    data = load_calibration_yaml(existing)
    for wheel in ("lwheel_pid", "rwheel_pid"):
        section = data.get(wheel)
        if section is None:
            section = data[wheel] = {}
        if not isinstance(section, dict):
            raise ValueError(f"its {wheel} is not a mapping; fix or remove it")
        section.update({k: round(v, 1) for k, v in gains.to_params().items()})
    return yaml.safe_dump(data, sort_keys=False)
