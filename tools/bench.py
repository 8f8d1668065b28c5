#!/usr/bin/env python3
"""Run every benchmark of the workspace in one process and print the figures side by side.

A benchmark is a module ``<package>/bench/bench_<name>.py`` with a function
``run(quick: bool = False) -> list[dict]``; each row has the keys

    bench, case, metric, ours, reference, reference_name, goal, met

(``reference``/``goal``/``met`` may be None).  The table shows ours next to the
reference and their ratio; all rows go to ``bench-results/bench-<UTC time>.json``
and ``bench-results/latest.json``, with the run's facts (date, commit, machine,
total time) under ``meta``.

A full run (no ``--quick``, no ``-k``) also writes ``docs/benchmarks.md``
(tools/bench_report.py).  A quick or ``-k`` run leaves that page alone, so a
partial run never replaces the full report; ``--report`` writes it anyway
(the page then says it is a quick / partial run).
``python tools/bench_report.py bench-results/latest.json`` rebuilds the page
from a stored JSON without running anything.

Usage:  python tools/bench.py [--quick] [-k SUBSTRING] [--report]
"""
from __future__ import annotations

import argparse
import datetime as dt
import importlib.util
import json
import os
import platform
import sys
import time
import traceback
from pathlib import Path

from bench_report import REPORT, collect_meta, write_report  # tools/ is this script's directory
from procs import stop_on_sigterm

ROOT = Path(__file__).resolve().parent.parent
OUT = ROOT / "bench-results"
KEYS = ("bench", "case", "metric", "ours", "reference", "reference_name", "goal", "met")


def discover() -> list[Path]:
    return sorted(p for p in ROOT.glob("*/bench/bench_*.py"))


def load(path: Path):
    spec = importlib.util.spec_from_file_location(f"chefbot_bench_{path.parent.parent.name}_{path.stem}", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def fmt(x) -> str:
    if x is None:
        return "-"
    if isinstance(x, float):
        return f"{x:.4g}"
    return str(x)


def print_table(rows: list[dict]) -> None:
    head = ("bench", "case", "metric", "ours", "reference", "ours/ref", "goal", "met")
    table = [head]
    for r in rows:
        ours, reference = r.get("ours"), r.get("reference")
        numeric = isinstance(ours, (int, float)) and isinstance(reference, (int, float))
        ratio = ours / reference if numeric and reference else None
        ref = fmt(r.get("reference"))
        if r.get("reference_name"):
            ref = f"{ref} ({r['reference_name']})"
        met = {True: "yes", False: "NO", None: "-"}[r.get("met")]
        table.append((r["bench"], r["case"], r["metric"], fmt(r["ours"]), ref, fmt(ratio), r.get("goal") or "-", met))
    widths = [max(len(str(row[i])) for row in table) for i in range(len(head))]
    for i, row in enumerate(table):
        print("  ".join(str(c).ljust(w) for c, w in zip(row, widths, strict=True)).rstrip())
        if i == 0:
            print("  ".join("-" * w for w in widths))


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="fewer repetitions (smoke run)")
    ap.add_argument("-k", dest="pattern", help="only benchmark files whose path contains this")
    ap.add_argument("--report", action="store_true",
                    help=f"write {REPORT.relative_to(ROOT)} even for a --quick or -k run")
    args = ap.parse_args()

    files = [p for p in discover() if not args.pattern or args.pattern in str(p)]
    if not files:
        print("[bench] no benchmarks found")
        return 1
    rows: list[dict] = []
    errors = 0
    failed: list[str] = []
    sources: dict[str, str] = {}
    meta = collect_meta()  # the commit and tree state the run starts from
    t0 = time.monotonic()
    for path in files:
        rel = path.relative_to(ROOT)
        print(f"[bench] {rel} ...", flush=True)
        try:
            got = load(path).run(quick=args.quick)
        except Exception:  # noqa: BLE001 - one broken benchmark must not hide the others' figures
            traceback.print_exc()
            errors += 1
            failed.append(str(rel))
            continue
        for r in got:
            missing = [k for k in ("bench", "case", "metric", "ours") if k not in r]
            if missing:
                print(f"[bench] {rel}: row without {missing}: {r}")
                errors += 1
                continue
            rows.append({k: r.get(k) for k in KEYS})
            sources.setdefault(str(r["bench"]), str(rel))
    print()
    print_table(rows)
    OUT.mkdir(exist_ok=True)
    stamp = dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ")
    seconds = round(time.monotonic() - t0, 1)
    meta.update(seconds=seconds, quick=args.quick, pattern=args.pattern, failed=failed, sources=sources,
                load_end=round(os.getloadavg()[0], 2))
    doc = {"time_utc": stamp, "host": platform.node(), "python": platform.python_version(),
           "quick": args.quick, "seconds": seconds, "meta": meta, "rows": rows}
    for name in (f"bench-{stamp}.json", "latest.json"):
        (OUT / name).write_text(json.dumps(doc, indent=2) + "\n")
    print(f"\n[bench] {len(rows)} figures from {len(files)} benchmarks in {doc['seconds']} s; "
          f"JSON: {(OUT / 'latest.json').relative_to(ROOT)}; {errors} errors")
    if args.report or not (args.quick or args.pattern):
        page = write_report(doc, source_json=str((OUT / f"bench-{stamp}.json").relative_to(ROOT)))
        print(f"[bench] report: {page.relative_to(ROOT)}")
    else:
        print(f"[bench] {REPORT.relative_to(ROOT)} left as it is (quick or -k run; --report writes it)")
    return 1 if errors else 0


if __name__ == "__main__":
    stop_on_sigterm()
    sys.exit(main())
