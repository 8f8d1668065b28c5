"""tools/bench_report.py: docs/benchmarks.md rendered from fixed rows (pure, no benchmark runs)."""
from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[2]


sys.path.insert(0, str(ROOT / "tools"))
import bench_report as report  # noqa: E402  (tools/ is no package)

ROWS = [
    {"bench": "serial parser", "case": "parse_line on firmware lines", "metric": "lines/s", "ours": 123456.78,
     "reference": 181.0, "reference_name": "firmware line rate", "goal": ">= 10 x reference", "met": True},
    {"bench": "serial parser", "case": "a | pipe\nand a newline", "metric": "ms", "ours": 0.012345,
     "reference": None, "reference_name": None, "goal": None, "met": None},
    {"bench": "firmware", "case": "flash (toolchain missing: arm-none-eabi-size not found)", "metric": "bytes",
     "ours": None, "reference": 262144, "reference_name": "TM4C123GH6PM flash", "goal": "<= 50 % of flash",
     "met": None},
    {"bench": "firmware", "case": "share of flash", "metric": "%", "ours": 2.5694, "reference": 50,
     "reference_name": None, "goal": "<= 50 %", "met": False},
    {"bench": "firmware", "case": "nan and inf", "metric": "s", "ours": float("nan"), "reference": float("inf"),
     "reference_name": "no limit", "goal": None, "met": None},
]
META = {"date_utc": "2026-11-27 12:00", "commit": "abc1234", "dirty": True, "cpu": "Test CPU @ 3 GHz",
        "cores": 8, "memory_bytes": 16 * 2**30, "os": "Debian GNU/Linux 12 (bookworm)", "python": "3.11.2",
        "kernel": "6.1.0-test", "seconds": 1872.4, "quick": False, "pattern": None, "failed": [],
        "sources": {"serial parser": "chefbot_bringup/bench/bench_serial.py"}}


def _table_rows(text: str, section: str) -> list[list[str]]:
    """Cells of the data rows of ``section``'s table."""
    part = text.split(f"## {section}\n", 1)[1].split("\n## ", 1)[0]
    lines = [ln for ln in part.splitlines() if ln.startswith("| ")][1:]   # drop the heading row
    return [[c.strip() for c in ln.strip("|").split(" | ")] for ln in lines]


@pytest.mark.parametrize(("value", "text"), [
    (None, "-"), (0.0, "0"), (0, "0"), (12, "12"), (123456, "123 456"), (123456.78, "123 457"),
    (999.94, "999.9"), (1.23456, "1.235"), (0.0123456, "0.01235"), (1e-5, "1e-05"), (-2500.4, "-2 500"),
    (float("nan"), "NaN"), (float("inf"), "inf"), (True, "yes"), ("skipped", "skipped")])
def test_fmt_value(value, text):
    assert report.fmt_value(value) == text


def test_fmt_met_and_duration():
    assert [report.fmt_met(m) for m in (True, False, None)] == ["yes", "NO", "-"]
    assert report.fmt_duration(45.23) == "45.2 s"
    assert report.fmt_duration(1872.4) == "31 min 12 s"
    assert report.fmt_duration(3725) == "1 h 02 min"
    assert report.fmt_duration(None) == "unknown"


def test_header_has_the_run_facts():
    text = report.render_report(ROWS, META)
    assert text.startswith("# Benchmarks\n")
    assert "do not edit by hand" in text
    assert "| Date (UTC) | 2026-11-27 12:00 |" in text
    assert "| Commit | abc1234 + uncommitted changes |" in text
    assert "| Machine | Test CPU @ 3 GHz, 8 cores, 16.0 GiB memory |" in text
    assert "| OS | Debian GNU/Linux 12 (bookworm), kernel 6.1.0-test |" in text
    assert "| Python | 3.11.2 |" in text
    assert "| Total time | 31 min 12 s |" in text
    assert "| Run | full run |" in text
    assert "5 figures from 2 benchmarks. Goal met: 1; not met (NO): 1; no goal (-): 3." in text
    clean = report.render_report(ROWS, dict(META, dirty=False))
    assert "| Commit | abc1234 |" in clean


def test_one_section_per_bench_in_row_order():
    text = report.render_report(ROWS, META)
    assert text.index("## serial parser") < text.index("## firmware")
    assert "Source: `chefbot_bringup/bench/bench_serial.py`" in text
    assert "[serial parser](#serial-parser)" in text
    serial = _table_rows(text, "serial parser")
    assert serial[0] == ["parse_line on firmware lines", "lines/s", "123 457", ">= 10 x reference",
                         "181 (firmware line rate)", "yes"]
    # pipes escaped, line break folded: the row keeps its six cells
    assert serial[1] == ["a \\| pipe and a newline", "ms", "0.01235", "-", "-", "-"]
    fw = _table_rows(text, "firmware")
    assert fw[0] == ["flash (toolchain missing: arm-none-eabi-size not found)", "bytes", "-", "<= 50 % of flash",
                     "262 144 (TM4C123GH6PM flash)", "-"]
    assert fw[1] == ["share of flash", "%", "2.569", "<= 50 %", "50", "NO"]
    assert fw[2] == ["nan and inf", "s", "NaN", "-", "inf (no limit)", "-"]


def test_partial_runs_and_failures_are_marked():
    meta = dict(META, quick=True, pattern="bench_serial", failed=["chefbot_sim/bench/bench_sim.py"])
    text = report.render_report(ROWS, meta)
    assert "quick run" in text and "only benchmark files matching `bench_serial`" in text
    assert "* `chefbot_sim/bench/bench_sim.py`" in text


def test_missing_meta_and_no_rows():
    text = report.render_report([], {})
    assert "| Commit | unknown |" in text and "| Total time | unknown |" in text
    assert "0 figures from 0 benchmarks." in text


def test_render_is_pure():
    before = json.dumps([ROWS, META])
    first = report.render_report(ROWS, META)
    assert report.render_report(ROWS, META) == first
    assert json.dumps([ROWS, META]) == before   # inputs untouched


def test_cli_regenerates_from_json(tmp_path):
    """An old-style JSON (no ``meta``) renders too, without running any benchmark."""
    doc = {"time_utc": "20261127T120000Z", "host": "h", "python": "3.11.2", "quick": False, "seconds": 12.5,
           "rows": ROWS[:2]}
    src = tmp_path / "latest.json"
    src.write_text(json.dumps(doc))
    out = tmp_path / "benchmarks.md"
    res = subprocess.run([sys.executable, str(ROOT / "tools" / "bench_report.py"), str(src), "-o", str(out)],
                         capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    text = out.read_text()
    assert "| Date (UTC) | 2026-11-27 12:00 |" in text
    assert "| Total time | 12.5 s |" in text
    assert "## serial parser" in text


def test_load_average_at_start_and_end_is_shown():
    text = report.render_report(ROWS, dict(META, load_start=0.42, load_end=7.5))
    assert "| Load average (1 min) | 0.42 at the start, 7.5 at the end |" in text
    assert "| Load average (1 min) | unknown |" in report.render_report(ROWS, {})
