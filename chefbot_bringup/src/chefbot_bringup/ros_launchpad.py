"""ROS side of launchpad_node (imports rospy for logging and time): the serial link to the board.

:class:`SerialLink` owns the port: a reader thread that never dies (reconnects with backoff
after open failures, unplugs and silence), writes under one port lock, and the shutdown
sequence (stop + reset twice, as the book's driver does).  The protocol logic is
:class:`chefbot_bringup.launchpad.LaunchpadCore`'s; the node only publishes.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import Any

import rospy
import serial

from chefbot_bringup import launchpad_protocol as proto
from chefbot_bringup.launchpad import LaunchpadConfig, LaunchpadCore


class SerialLink:
    """The board's serial port for ``core``: ``on_message(msg, extra)`` gets each parsed line, and
    ``on_change()`` is called when the link state changes (connected, error) for the diagnostics."""

    def __init__(self, p: LaunchpadConfig, core: LaunchpadCore, on_message: Callable[[Any, Any], None],
                 on_change: Callable[[], None]) -> None:
        self.p, self.core, self.on_message, self.on_change = p, core, on_message, on_change
        self._ser: serial.Serial | None = None
        self._io_lock = threading.Lock()      # guards _ser for the writer and the reader
        self.stopping = threading.Event()
        self.last_error = ""
        self.last_cmd_write = float("-inf")  # monotonic time of the last motor command written (s)
        self.reader = threading.Thread(target=self._reader_loop, name="launchpad_reader", daemon=True)

    def start(self) -> None:
        """Start the reader thread (it opens the port)."""
        self.reader.start()

    # ---------------------------------------------------------------- writing
    def send_command(self) -> None:
        """Write the current ``s`` line now; zero while the board is not heard from (no
        feedback: it must not be driven).  Built and written under the port lock, so two
        callbacks cannot interleave or send an older pair after a newer one."""
        with self._io_lock:
            if self._ser is None or not self.core.connected or self.stopping.is_set():
                return
            now = time.monotonic()
            if self._write_locked(self.core.command(now)):
                self.last_cmd_write = now

    def write(self, data: bytes) -> bool:
        """Write ``data`` if the port is open; False (error kept for the diagnostics) if not written."""
        with self._io_lock:
            return self._write_locked(data)

    def _write_locked(self, data: bytes) -> bool:
        ser = self._ser
        if ser is None:
            return False
        try:
            ser.write(data)
            return True
        except (serial.SerialException, OSError) as exc:
            self.last_error = f"write failed: {exc}"
            return False

    # ---------------------------------------------------------------- link
    def _open(self) -> bool:
        try:
            ser = serial.Serial(self.p.port, self.p.baud, timeout=0.05, write_timeout=0.2)
            ser.reset_input_buffer()
        except (serial.SerialException, OSError, ValueError) as exc:
            self._set_error(f"cannot open {self.p.port}: {exc}")
            return False
        with self._io_lock:
            self._ser = ser
        self.core.on_open(time.monotonic())
        rospy.loginfo("launchpad: opened %s at %d baud; motors held at 0 until the board talks",
                      self.p.port, self.p.baud)
        return True

    def _close(self, reason: str) -> None:
        with self._io_lock:
            ser, self._ser = self._ser, None
        if ser is not None:
            try:
                ser.write(self.core.stop_command())  # best effort: the port may be gone
            except (serial.SerialException, OSError):
                pass
            try:
                ser.close()
            except (serial.SerialException, OSError):
                pass
        if self.core.connected:
            self.core.on_close()
            self._set_error(reason)

    def _set_error(self, reason: str) -> None:
        if reason != self.last_error:
            rospy.logerr("launchpad: %s", reason)
        self.last_error = reason
        self.on_change()

    def _reader_loop(self) -> None:
        backoff = 0.1
        while not self.stopping.is_set() and not rospy.is_shutdown():
            try:
                if self._ser is None:
                    if not self._open():
                        self.stopping.wait(backoff)
                        backoff = min(backoff * 2, self.p.backoff_max)
                        continue
                    backoff = 0.1
                self._read_once()
            except Exception as exc:  # noqa: BLE001 - the reader must never die; report and go on
                self._close(f"reader error: {exc!r}")
                self.stopping.wait(backoff)

    def _read_once(self) -> None:
        ser = self._ser
        try:
            data = ser.read(max(1, ser.in_waiting))
        except (serial.SerialException, OSError, TypeError) as exc:
            self._close(f"{self.p.port} lost: {exc}")
            return
        now = time.monotonic()
        if data:
            heard_before = self.core.heard
            for msg, extra in self.core.on_bytes(data, now):
                self.on_message(msg, extra)
            if self.core.heard and not heard_before:
                rospy.loginfo("launchpad: connected to %s: the board talks; driving enabled", self.p.port)
                self.on_change()
        if self.core.silent(now):
            self._close(f"no valid line from {self.p.port} for {self.p.silence_timeout:.1f} s; reconnecting")

    def shutdown(self) -> None:
        """Stop the motors and reset the board twice, as the book's driver does; then close the port.
        The caller sets :attr:`stopping` and stops its timers first."""
        self.stopping.set()
        self.write(self.core.stop_command())
        for _ in range(2):
            self.write(proto.format_reset())
        self.reader.join(timeout=1.0)
        with self._io_lock:
            if self._ser is not None:
                try:
                    self._ser.close()
                except (serial.SerialException, OSError):
                    pass
                self._ser = None


def warn_if_clock_missing(wait: float = 5.0) -> None:
    """Warn once if /use_sim_time is set but no /clock arrived within ``wait`` s of wall time:
    every ROS-time timer of this launch (control loop, PIDs, twist_to_motors) is frozen then."""
    def check() -> None:
        if rospy.get_param("/use_sim_time", False) and rospy.get_rostime().is_zero() and not rospy.is_shutdown():
            rospy.logwarn("launchpad_node: /use_sim_time is true but no /clock arrived in %.0f s: ROS-time timers "
                          "are frozen, the motors get no commands. Left over from a simulation? Run "
                          "'rosparam set /use_sim_time false' and restart this launch (or restart roscore).", wait)
    timer = threading.Timer(wait, check)
    timer.daemon = True
    timer.start()
