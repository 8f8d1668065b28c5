"""Firmware figures: flash and RAM of the Cortex-M4F build, and the command parser's throughput.

* Flash / RAM: ``make -C firmware arm`` (core/ for the TM4C123GH6PM, -Os, plus
  the link probe arm/size_probe.cpp: core + newlib-nano start-up after
  --gc-sections) into a temporary build directory, measured with
  ``arm-none-eabi-size``.  Flash = .text + .data, static RAM = .data + .bss.
  Energia's own runtime (Serial, Wire, start-up) is not in the probe.
  Without the arm toolchain (Debian: gcc-arm-none-eabi, libnewlib-arm-none-eabi)
  the rows say so and carry no figure.
* Command parser: ``core/command_parser.cpp`` built for this PC (g++ -O2) and
  fed checksummed ``s`` commands byte by byte, as the board's loop does.  The
  figure is this PC's, not the 80 MHz board's; the reference is the most
  command lines the 115 200 baud link can carry.
"""
from __future__ import annotations

import shutil
import subprocess
import sys
import tempfile
from pathlib import Path

FW = Path(__file__).resolve().parents[1]
ROOT = FW.parent
FLASH_BYTES = 256 * 1024        # TM4C123GH6PM: 256 KiB flash
SRAM_BYTES = 32 * 1024          # TM4C123GH6PM: 32 KiB SRAM
MAKE_BUDGET = 32768             # firmware/Makefile FLASH_LIMIT
LINK_BYTES_PER_S = 11520        # 115200 baud 8N1
ARM_PREFIX = "arm-none-eabi-"

PARSER_MAIN = r"""
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include "command_parser.h"
int main(int argc, char** argv) {
  const char* line = argv[1];
  const long n = std::atol(argv[2]);
  const size_t len = std::strlen(line);
  chefbot::CommandParser parser;
  chefbot::Command cmd;
  long speeds = 0;
  auto t0 = std::chrono::steady_clock::now();
  for (long i = 0; i < n; ++i)
    for (size_t k = 0; k < len; ++k)
      if (parser.push(static_cast<uint8_t>(line[k]), cmd) == chefbot::RxEvent::Speed) speeds += cmd.left;
  double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::printf("%ld %.9f %ld\n", n, s, speeds);
  return speeds == n * 300 ? 0 : 1;
}
"""


def _size(elf_or_objs: list[Path]) -> tuple[int, int, int]:
    """(text, data, bss) summed over the files, by arm-none-eabi-size."""
    out = subprocess.run([ARM_PREFIX + "size", "-t", *map(str, elf_or_objs)], capture_output=True, text=True,
                         check=True).stdout.splitlines()
    total = out[-1].split() if len(elf_or_objs) > 1 else out[1].split()
    return int(total[0]), int(total[1]), int(total[2])


def flash_rows() -> list[dict]:
    base = {"bench": "firmware", "metric": "bytes"}
    missing = [t for t in ("g++", "gcc", "size") if shutil.which(ARM_PREFIX + t) is None]
    if missing:
        case = (f"toolchain missing ({', '.join(ARM_PREFIX + t for t in missing)} not found; Debian: "
                f"gcc-arm-none-eabi libnewlib-arm-none-eabi): flash not measured")
        return [dict(base, case=case, ours=None, reference=FLASH_BYTES, reference_name="TM4C123GH6PM flash (256 KiB)",
                     goal="<= 50 % of flash", met=None)]
    with tempfile.TemporaryDirectory(prefix="chefbot_arm_") as tmp:
        res = subprocess.run(["make", "-C", str(FW), "arm", f"BUILD={tmp}"], capture_output=True, text=True,
                             check=False)
        elf = Path(tmp) / "arm" / "size_probe.elf"
        objs = sorted((Path(tmp) / "arm" / "core").glob("*.o"))
        if not elf.is_file() or not objs:
            raise RuntimeError(f"make arm failed (exit {res.returncode}):\n{res.stdout[-2000:]}{res.stderr[-2000:]}")
        text, data, bss = _size([elf])
        ctext, cdata, _ = _size(objs)
    flash, ram, core = text + data, data + bss, ctext + cdata
    share = 100.0 * flash / FLASH_BYTES
    return [
        dict(base, case=f"linked image: core + newlib-nano start-up, -Os, --gc-sections (= {share:.1f} % of flash; "
                        f"Energia's runtime not included)",
             ours=flash, reference=FLASH_BYTES, reference_name="TM4C123GH6PM flash (256 KiB)",
             goal="<= 50 % of flash", met=flash <= FLASH_BYTES // 2),
        dict(base, case=f"core objects, everything in core/ before linking ({len(objs)} files)", ours=core,
             reference=MAKE_BUDGET, reference_name="make arm budget (firmware/Makefile)", goal="<= budget",
             met=core <= MAKE_BUDGET),
        dict(base, case=f"linked image: static RAM, .data + .bss, no stack "
                        f"(= {100.0 * ram / SRAM_BYTES:.1f} % of SRAM)",
             ours=ram, reference=SRAM_BYTES, reference_name="TM4C123GH6PM SRAM (32 KiB)", goal=None, met=None),
    ]


def parser_rows(quick: bool) -> list[dict]:
    line = b"s 300 -300"
    crc = 0
    for byte in line:   # CRC-8/SMBUS (PROTOCOL.md)
        crc ^= byte
        for _ in range(8):
            crc = ((crc << 1) ^ 0x07) & 0xFF if crc & 0x80 else (crc << 1) & 0xFF
    wire = line + b" *%02X\r" % crc
    cxx = shutil.which("g++") or shutil.which("c++")
    base = {"bench": "firmware", "metric": "lines/s"}
    ref = round(LINK_BYTES_PER_S / len(wire), 1)
    ref_name = f"115200 baud / {len(wire)} B per command"
    if cxx is None:
        return [dict(base, case="command parser: no host C++ compiler (g++), not measured", ours=None,
                     reference=ref, reference_name=ref_name, goal=None, met=None)]
    with tempfile.TemporaryDirectory(prefix="chefbot_parser_") as tmp:
        src = Path(tmp) / "bench_parser.cpp"
        src.write_text(PARSER_MAIN)
        exe = Path(tmp) / "bench_parser"
        subprocess.run([cxx, "-std=c++11", "-O2", f"-I{FW / 'core'}", str(src), str(FW / "core" / "command_parser.cpp"),
                        str(FW / "core" / "crc8.cpp"), "-o", str(exe)], check=True, capture_output=True, text=True)
        n = 200_000 if quick else 2_000_000
        best = float("inf")
        for _ in range(3 if quick else 7):
            out = subprocess.run([str(exe), wire.decode(), str(n)], check=True, capture_output=True, text=True)
            best = min(best, float(out.stdout.split()[1]))
    rate = n / best
    return [dict(base, case=f"C++ command parser (core/command_parser.cpp, g++ -O2 on this PC, not the board), "
                            f"'{line.decode()} *{crc:02X}' byte by byte ({1e9 / rate:.0f} ns/line)",
                 ours=round(rate), reference=ref, reference_name=ref_name, goal=">= 10 x reference",
                 met=rate >= 10 * ref)]


def run(quick: bool = False) -> list[dict]:
    """Benchmark rows (see tools/bench.py)."""
    return flash_rows() + parser_rows(quick)


if __name__ == "__main__":
    for r in run(quick="--quick" in sys.argv):
        print(r)
