"""tools/bench_report.py: docs/benchmarks.md and its store rendered and merged from fixed rows (pure, no
benchmark runs)."""
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
        "sources": {"serial parser": "chefbot_bringup/bench/bench_serial.py",
                    "firmware": "firmware/bench/bench_firmware.py"},
        "file_seconds": {"chefbot_bringup/bench/bench_serial.py": 12.5, "firmware/bench/bench_firmware.py": 1859.9}}


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


def _doc(rows, **meta) -> dict:
    return {"meta": dict(META, **meta), "rows": rows}


def test_header_has_the_machine_and_a_table_of_runs():
    text = report.render_report(ROWS, META)
    assert text.startswith("# Benchmarks\n")
    assert "do not edit by hand" in text
    assert "| Machine | Test CPU @ 3 GHz, 8 cores, 16.0 GiB memory |" in text
    assert "| OS | Debian GNU/Linux 12 (bookworm), kernel 6.1.0-test, Python 3.11.2 |" in text
    assert "5 figures from 2 benchmarks. Goal met: 1; not met (NO): 1; no goal (-): 3." in text
    runs = [ln for ln in text.splitlines() if ln.startswith("| [")]
    assert runs[0] == ("| [serial parser](#serial-parser) | 2026-11-27 12:00 | abc1234 + uncommitted changes | "
                       "12.5 s | full run | unknown |")
    assert "| 31 min 00 s |" in runs[1]
    clean = report.render_report(ROWS, dict(META, dirty=False))
    assert "| 2026-11-27 12:00 | abc1234 | 12.5 s |" in clean


def test_one_section_per_bench_with_its_run():
    text = report.render_report(ROWS, META)
    assert text.index("## serial parser") < text.index("## firmware")
    assert ("Source: `chefbot_bringup/bench/bench_serial.py`. Measured 2026-11-27 12:00 UTC at abc1234 + "
            "uncommitted changes (full run; 12.5 s).") in text
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


def test_a_partial_run_replaces_only_its_sections():
    store = report.merge(report.empty_store(), _doc(ROWS))
    newer = dict(ROWS[0], ours=99.0)
    again = report.merge(store, _doc([newer], date_utc="2026-12-01 09:30", commit="def5678", dirty=False,
                                     pattern="bench_serial", settings={"CHEFBOT_X": "3"}))
    names = [sec["name"] for sec in again["benches"]]
    assert names == ["serial parser", "firmware"]            # ordered by source file
    serial, firmware = again["benches"]
    assert [r["ours"] for r in serial["rows"]] == [99.0]     # replaced whole: the old second row is gone
    assert serial["run"]["commit"] == "def5678" and serial["run"]["seconds"] == 12.5
    assert json.dumps(firmware) == json.dumps(store["benches"][1])   # untouched, with its own run (NaN != NaN)
    text = report.render_store(again)
    assert "Measured 2026-12-01 09:30 UTC at def5678 (run of `-k bench_serial`, `CHEFBOT_X=3`; 12.5 s)." in text
    assert "Measured 2026-11-27 12:00 UTC at abc1234 + uncommitted changes (full run; 31 min 00 s)." in text


def test_a_failed_bench_keeps_its_figures_marked_and_gone_files_drop():
    store = report.merge(report.empty_store(), _doc(ROWS))
    failed = report.merge(store, _doc([], date_utc="2026-12-01 10:00", commit="fff0000",
                                      failed=["firmware/bench/bench_firmware.py"]))
    assert json.dumps(failed["benches"][1]["rows"]) == json.dumps(store["benches"][1]["rows"])
    text = report.render_store(failed)
    assert "* `firmware/bench/bench_firmware.py` (2026-12-01 10:00, fff0000)" in text
    gone = report.merge(store, _doc([]), existing_sources={"chefbot_bringup/bench/bench_serial.py"})
    assert [sec["name"] for sec in gone["benches"]] == ["serial parser"]


def test_merge_and_render_are_pure():
    store = report.merge(report.empty_store(), _doc(ROWS))
    before = json.dumps([ROWS, META, store])
    first = report.render_store(store)
    assert report.render_store(store) == first
    report.merge(store, _doc(ROWS[:1], commit="x"))
    assert json.dumps([ROWS, META, store]) == before   # inputs untouched


def test_quick_runs_are_named():
    text = report.render_report(ROWS, dict(META, quick=True, pattern="bench_serial"))
    assert "quick run of `-k bench_serial`" in text


def test_missing_meta_and_no_rows():
    text = report.render_report(ROWS[:1], {})
    assert "Measured unknown UTC at unknown (full run)." in text
    assert "0 figures from 0 benchmarks." in report.render_report([], {})


@pytest.mark.parametrize("content", ["{not json", "[]", '{"format": 1, "benches": [{"name": 3}]}',
                                     '{"format": 99, "benches": []}'])
def test_a_corrupt_store_is_an_error_not_an_empty_page(tmp_path, content):
    store = tmp_path / "benchmarks.json"
    store.write_text(content)
    with pytest.raises(ValueError, match="benchmarks.json"):
        report.load_store(store)
    res = subprocess.run([sys.executable, str(ROOT / "tools" / "bench_report.py"), "--store", str(store),
                          "-o", str(tmp_path / "benchmarks.md")],
                         capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 1 and "benchmarks.json" in res.stderr
    assert store.read_text() == content and not (tmp_path / "benchmarks.md").exists()


def test_cli_merges_stored_runs_into_the_store(tmp_path):
    """An old-style JSON (no ``meta``) merges too, without running any benchmark; a second run of one
    bench replaces its section only."""
    first = {"time_utc": "20261127T120000Z", "host": "h", "python": "3.11.2", "quick": False, "seconds": 12.5,
             "rows": ROWS}
    second = {"meta": dict(META, date_utc="2026-12-01 08:00", commit="bbb2222"), "rows": ROWS[2:3]}
    paths = []
    for i, doc in enumerate((first, second)):
        paths.append(tmp_path / f"run{i}.json")
        paths[-1].write_text(json.dumps(doc))
    store, out = tmp_path / "benchmarks.json", tmp_path / "benchmarks.md"
    cmd = [sys.executable, str(ROOT / "tools" / "bench_report.py"), "--store", str(store), "-o", str(out)]
    res = subprocess.run(cmd + [str(p) for p in paths], capture_output=True, text=True, timeout=60, check=False)
    assert res.returncode == 0, res.stderr
    text = out.read_text()
    assert "Measured 2026-11-27 12:00 UTC at unknown (full run)." in text      # serial parser
    assert "Measured 2026-12-01 08:00 UTC at bbb2222 + uncommitted changes" in text      # firmware
    assert len(_table_rows(text, "firmware")) == 1 and len(_table_rows(text, "serial parser")) == 2
    out.unlink()
    res = subprocess.run(cmd, capture_output=True, text=True, timeout=60, check=False)   # rebuild only
    assert res.returncode == 0, res.stderr
    assert out.read_text() == text


def test_load_average_at_start_and_end_is_shown():
    text = report.render_report(ROWS, dict(META, load_start=0.42, load_end=7.5))
    assert "| 0.42 at the start, 7.5 at the end |" in text


def test_the_repository_page_is_the_store_rendered():
    """docs/benchmarks.md is what tools/bench_report.py renders from docs/benchmarks.json (nobody edited
    either by hand, and a merge wrote both)."""
    assert report.REPORT.read_text() == report.render_store(report.load_store(report.STORE))
