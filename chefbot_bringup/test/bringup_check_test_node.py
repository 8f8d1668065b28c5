#!/usr/bin/env python3
"""rostest node for bringup_check.test: the guided wiring check against the board emulator.

Each case steps a VirtualBoard (our firmware core on a pseudo-terminal, optionally with build
faults) in real time on a thread, runs ``roslaunch chefbot_bringup bringup_check.launch`` in its own
process group against this test's master, and reads the exit code, the output and the YAML report.
"""
from __future__ import annotations

import os
import signal
import subprocess
import sys
import tempfile
import threading
import time
import unittest
from pathlib import Path

import rostest
import yaml

from chefbot_firmware.host import LEFT, RIGHT
from chefbot_firmware.virtual_board import BuildFaults, VirtualBoard

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from procs import group_tree, kill_group, stop_tracked


class RunningBoard:
    """A VirtualBoard stepped in real time on a thread until closed."""

    def __init__(self, link: str, faults: BuildFaults | None = None, motor_strength: float = 1.0) -> None:
        self.board = VirtualBoard(link, faults=faults)
        for m in self.board.motors:
            m.free_speed *= motor_strength
        self.lock = threading.Lock()
        self.max_duty = 0.0          # largest |duty| the firmware applied (any wheel)
        self._stop = threading.Event()
        self.error: BaseException | None = None
        self.thread = threading.Thread(target=self._run, daemon=True)
        self.thread.start()

    def _run(self) -> None:
        last = time.monotonic()
        try:
            while not self._stop.is_set():
                time.sleep(0.002)
                now = time.monotonic()
                with self.lock:
                    self.board.step(min(now - last, 0.05))
                    for side in (LEFT, RIGHT):
                        self.max_duty = max(self.max_duty, abs(self.board.fw.wheel_duty(side)))
                last = now
        except BaseException as exc:  # noqa: BLE001 - reported by the test
            self.error = exc

    def duties(self) -> tuple[float, float]:
        with self.lock:
            return self.board.fw.wheel_duty(LEFT), self.board.fw.wheel_duty(RIGHT)

    def close(self) -> None:
        self._stop.set()
        self.thread.join(5.0)
        self.board.close()


def run_launch(port: str, report: str, timeout: float, interrupt_when=None,
               extra: tuple[str, ...] = ()) -> tuple[int | None, str]:
    """roslaunch bringup_check.launch (its exit code is roslaunch's, 0 however the check ended); with
    ``interrupt_when`` (a predicate on the output so far) Ctrl-C the launch as soon as it holds.
    Returns (exit code or None if it had to be killed, output)."""
    out = tempfile.TemporaryFile()
    proc = subprocess.Popen(["roslaunch", "--disable-title", "chefbot_bringup", "bringup_check.launch",
                             f"port:={port}", "interactive:=false", f"report:={report}", *extra],
                            stdin=subprocess.DEVNULL, stdout=out, stderr=subprocess.STDOUT, start_new_session=True)
    tracked = group_tree(proc.pid)
    deadline = time.monotonic() + timeout
    interrupted = False
    while proc.poll() is None and time.monotonic() < deadline:
        tracked.update(group_tree(proc.pid))
        if interrupt_when is not None and not interrupted:
            out.seek(0)
            if interrupt_when(out.read().decode(errors="replace")):
                os.killpg(proc.pid, signal.SIGINT)       # the terminal's Ctrl-C: the whole group
                interrupted = True
                deadline = min(deadline, time.monotonic() + 20.0)
        time.sleep(0.05)
    rc = proc.poll()
    if rc is None:
        kill_group(proc.pid)
    proc.wait()
    stop_tracked(tracked)
    out.seek(0)
    return rc, out.read().decode(errors="replace")


class TestBringupCheck(unittest.TestCase):
    def setUp(self) -> None:
        self.tmp = tempfile.TemporaryDirectory(prefix="bringup_check_")
        self.link = os.path.join(self.tmp.name, "lp")
        self.report = os.path.join(self.tmp.name, "report.yaml")
        self.board: RunningBoard | None = None

    def tearDown(self) -> None:
        if self.board is not None:
            self.board.close()
        self.tmp.cleanup()

    def check(self, faults: BuildFaults | None = None, timeout: float = 90.0, motor_strength: float = 1.0,
              **kw) -> tuple[int | None, str, dict]:
        self.board = RunningBoard(self.link, faults, motor_strength)
        rc, text = run_launch(self.link, self.report, timeout, **kw)
        self.assertIsNone(self.board.error, f"the board emulator failed: {self.board.error!r}")
        # the motors: stopped when the check ended (the firmware's own applied duty)
        self.assertEqual(self.board.duties(), (0.0, 0.0), text[-2000:])
        rep = yaml.safe_load(Path(self.report).read_text()) if os.path.exists(self.report) else {}
        return rc, text, rep

    def test_1_correct_robot_passes(self) -> None:
        rc, text, rep = self.check()
        self.assertIsNotNone(rc, f"the launch did not end with the check:\n{text[-3000:]}")
        self.assertIn("ALL OK", text, text[-3000:])
        self.assertNotIn("exit code", text)          # roslaunch reports the node's exit code only if not 0
        self.assertTrue(rep["ok"], rep)
        self.assertEqual(rep["faults"], [])
        self.assertIs(rep["motors_stopped"], True)
        self.assertEqual([s["name"] for s in rep["steps"]], ["board", "motors", "pid"])
        self.assertGreater(self.board.max_duty, 0.2, "the motors never ran")

    def test_2_two_wiring_faults_are_named_with_their_fixes(self) -> None:
        rc, text, rep = self.check(BuildFaults(left_leads_swapped=True, right_encoder_reversed=True))
        self.assertIsNotNone(rc, f"the launch did not end with the check:\n{text[-3000:]}")
        self.assertIn("FAULTS: direction_reversed, direction_reversed", text)
        self.assertIn("exit code 1", text)
        self.assertEqual(sorted(rep["faults"]), ["direction_reversed", "direction_reversed"], rep)
        sides = sorted(v["side"] for s in rep["steps"] for v in s["verdicts"] if not v["ok"])
        self.assertEqual(sides, ["left", "right"])
        self.assertIn("invert_left", text)
        self.assertIn("invert_right_encoder", text)
        self.assertIn("pid: skipped", text)
        self.assertIs(rep["motors_stopped"], True)

    def test_3_motors_swapped(self) -> None:
        rc, text, rep = self.check(BuildFaults(motors_swapped=True))
        self.assertIsNotNone(rc, f"the launch did not end with the check:\n{text[-3000:]}")
        self.assertEqual(rep["faults"], ["left_right_swapped"], rep)

    def test_4_ctrl_c_during_a_motor_run_stops_the_motors(self) -> None:
        rc, text, rep = self.check(interrupt_when=lambda t: "left motor forward" in t, timeout=60.0)
        self.assertIsNotNone(rc, f"the launch did not end after Ctrl-C:\n{text[-2000:]}")
        self.assertNotIn("Traceback", text, text[-2000:])
        self.assertIn("motors stopped (the board confirms 0/0)\ninterrupted", text, text[-2000:])

    def test_6_autotune_writes_better_gains_into_the_calibration_file(self) -> None:
        calib = os.path.join(self.tmp.name, "calibration.yaml")
        Path(calib).write_text("ticks_meter: 29950  # from calibrate_odometry\n")
        rc, text, rep = self.check(motor_strength=0.8, timeout=120.0,     # a motor 20 % weaker than configured
                                   extra=("autotune:=true", "write_gains:=true", f"calibration:={calib}"))
        self.assertIsNotNone(rc, text[-3000:])
        steps = {s["name"]: s for s in rep["steps"]}
        self.assertFalse(steps["pid"]["ok"], "today's gains should not reach the target on the weaker motor")
        # the report's own steps, not the launch's tail (which ends with roslaunch's summary)
        self.assertTrue(steps["pid_autotuned"]["ok"], steps["pid_autotuned"])
        self.assertTrue(steps["autotune"]["data"]["better"], steps["autotune"])
        data = yaml.safe_load(Path(calib).read_text())
        self.assertEqual(data["ticks_meter"], 29950)                      # kept
        self.assertEqual(data["lwheel_pid"], data["rwheel_pid"])
        self.assertEqual(data["lwheel_pid"]["Kp"], steps["autotune"]["data"]["proposed"]["Kp"])
        self.assertGreater(data["lwheel_pid"]["Ki"], 1000.0)
        self.assertIn(f"calibration:={calib}", text)

    def test_5_no_board_ends_with_the_reason(self) -> None:
        rc, text = run_launch(os.path.join(self.tmp.name, "no_such_port"), self.report, 60.0)
        self.assertIsNotNone(rc, text[-2000:])
        self.assertIn("cannot open", text, text[-2000:])
        self.assertIn("REQUIRED process [bringup_check", text, text[-2000:])


if __name__ == "__main__":
    rostest.rosrun("chefbot_bringup", "bringup_check_launch", TestBringupCheck, sys.argv)
