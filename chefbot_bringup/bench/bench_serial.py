"""Throughput of the PC side's serial parser against the line rate the firmware really sends.

The lines are recorded from our firmware core (the host build of firmware/core,
``chefbot_firmware.FirmwareHost``) in its default configuration with every
sensor present (IMU, sonar, battery) while the PC drives it with checksummed
``s`` commands at 30 Hz: exactly the bytes the board puts on the wire, paced
by its 115 200 baud UART model.  The same recording gives the firmware's line
rate (reference) and its byte rate against the link.  Then, on this machine:

* ``launchpad_protocol.parse_line`` alone, line by line;
* ``LaunchpadCore.on_bytes``, what launchpad_node runs per serial read: line
  assembly, parsing, CRC, encoder continuity, counters; fed in 64-byte reads.

Each is timed best-of-N (the least disturbed repetition).  Goal: at least ten
times the firmware's line rate, and more than a link full of such lines.
"""
from __future__ import annotations

import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
STATUS_HZ = 30                     # core/config.h status_rate_hz
LINES_PER_CYCLE = 6                # t e u s i b (PROTOCOL.md)
LINK_BYTES_PER_S = 11520           # 115200 baud 8N1, 10 bits per byte
GOAL_FACTOR = 10.0


def record(seconds: float = 10.0, warmup: float = 1.0) -> tuple[bytes, float]:
    """The firmware's output over ``seconds`` of simulated time after ``warmup``; (bytes, seconds)."""
    from chefbot_bringup.launchpad_protocol import format_command
    from chefbot_firmware.host import LEFT, RIGHT, FirmwareHost

    step_us = round(1e6 / STATUS_HZ)
    with FirmwareHost() as fw:
        fw.set_battery_volts(12.3)
        fw.set_ultrasonic_cm(57)
        fw.set_imu_quaternion(0.0012, -0.0034, 0.3827, 0.9239)
        out = bytearray()
        n_warm, n = round(warmup * STATUS_HZ), round(seconds * STATUS_HZ)
        for k in range(n_warm + n):
            fw.feed(format_command(300 + k % 7, -300 - k % 5))
            fw.wheel_advance(LEFT, 61 + k % 3)
            fw.wheel_advance(RIGHT, 59 + k % 4)
            fw.advance(step_us)
            data = fw.read_tx()
            if k >= n_warm:
                out += data
        return bytes(out), n * step_us / 1e6


def _best_rate(fn, n_lines: int, repeats: int) -> float:
    """Lines per second of ``fn()`` (which handles ``n_lines``), best of ``repeats``."""
    best = float("inf")
    for _ in range(repeats):
        t0 = time.perf_counter()
        fn()
        best = min(best, time.perf_counter() - t0)
    return n_lines / best


def measure(quick: bool = False) -> dict:
    from chefbot_bringup import launchpad_protocol as proto
    from chefbot_bringup.launchpad import LaunchpadCore, LineAssembler

    stream, sim_s = record(3.0 if quick else 10.0)
    lines = [x for x in LineAssembler().feed(stream) if isinstance(x, bytes)]
    # the recording starts mid-stream: the assembler drops the first (maybe cut) line
    bad = [x for x in lines[1:] if not _parses(proto, x)]
    if bad:
        raise RuntimeError(f"{len(bad)} recorded firmware lines do not parse, e.g. {bad[0]!r}")
    lines = lines[1:]
    n_wire = stream.count(b"\n")
    mean_bytes = len(stream) / n_wire
    repeats = 3 if quick else 7
    loops = 1 if quick else 5

    def parse_all() -> None:
        for _ in range(loops):
            for raw in lines:
                proto.parse_line(raw)

    chunks = [stream[i:i + 64] for i in range(0, len(stream), 64)]
    core = LaunchpadCore(max_ticks_per_s=20000.0)

    def node_path() -> None:
        for _ in range(loops):
            core.on_open(0.0)
            t = 0.0
            for c in chunks:
                t += 0.002
                core.on_bytes(c, t)

    parse_rate = _best_rate(parse_all, loops * len(lines), repeats)
    node_rate = _best_rate(node_path, loops * n_wire, repeats)
    return {"sim_s": sim_s, "wire_lines": n_wire, "wire_bytes": len(stream), "mean_bytes": mean_bytes,
            "fw_lines_per_s": n_wire / sim_s, "fw_bytes_per_s": len(stream) / sim_s,
            "link_lines_per_s": LINK_BYTES_PER_S / mean_bytes,
            "parse_lines_per_s": parse_rate, "node_lines_per_s": node_rate,
            "tags": sorted({ln.split(b"\t", 1)[0].decode() for ln in lines})}


def _parses(proto, raw: bytes) -> bool:
    try:
        proto.parse_line(raw)
    except proto.LineError:
        return False
    return True


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see tools/bench.py)."""
    from chefbot_firmware.host import FirmwareLibraryMissing

    try:
        m = measure(quick)
    except FirmwareLibraryMissing as err:   # the firmware's host build is needed for the recording
        return [{"bench": "serial parser", "case": f"skipped: {err}", "metric": "lines/s", "ours": None,
                 "reference": None, "reference_name": None, "goal": None, "met": None}]
    fw_rate, link_rate = m["fw_lines_per_s"], m["link_lines_per_s"]
    rec = (f"firmware core's output, {m['sim_s']:.0f} s at {STATUS_HZ} Hz, lines "
           f"{' '.join(m['tags'])}, mean {m['mean_bytes']:.1f} B/line")
    nominal = LINES_PER_CYCLE * STATUS_HZ + 1
    goal = f">= {GOAL_FACTOR:g} x the firmware's line rate"
    return [
        {"bench": "serial parser", "case": f"{rec}: line rate", "metric": "lines/s", "ours": round(fw_rate, 1),
         "reference": nominal, "reference_name": f"PROTOCOL.md: {LINES_PER_CYCLE} status lines x {STATUS_HZ} Hz + d",
         "goal": None, "met": None},
        {"bench": "serial parser", "case": f"{rec}: bytes on the wire", "metric": "B/s",
         "ours": round(m["fw_bytes_per_s"], 1), "reference": LINK_BYTES_PER_S,
         "reference_name": "115200 baud 8N1 link", "goal": "<= 50 % of the link (PROTOCOL.md budget)",
         "met": m["fw_bytes_per_s"] <= 0.5 * LINK_BYTES_PER_S},
        {"bench": "serial parser",
         "case": f"launchpad_protocol.parse_line on those lines ({1e6 / m['parse_lines_per_s']:.1f} us/line)",
         "metric": "lines/s", "ours": round(m["parse_lines_per_s"]), "reference": round(fw_rate, 1),
         "reference_name": "firmware line rate", "goal": goal, "met": m["parse_lines_per_s"] >= GOAL_FACTOR * fw_rate},
        {"bench": "serial parser", "case": "launchpad_protocol.parse_line vs a link full of such lines",
         "metric": "lines/s", "ours": round(m["parse_lines_per_s"]), "reference": round(link_rate, 1),
         "reference_name": "115200 baud / mean line length", "goal": ">= 1 x reference",
         "met": m["parse_lines_per_s"] >= link_rate},
        {"bench": "serial parser",
         "case": f"LaunchpadCore.on_bytes, 64-byte reads: assemble + parse + encoders + counters "
                 f"({1e6 / m['node_lines_per_s']:.1f} us/line)",
         "metric": "lines/s", "ours": round(m["node_lines_per_s"]), "reference": round(fw_rate, 1),
         "reference_name": "firmware line rate", "goal": goal, "met": m["node_lines_per_s"] >= GOAL_FACTOR * fw_rate},
    ]


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(r)
