#!/usr/bin/env python3
"""Run every benchmark of the workspace in one process and print the figures side by side.

A benchmark is a module ``<package>/bench/bench_<name>.py`` with a function
``run(quick: bool = False) -> list[dict]``; each row has the keys

    bench, case, metric, ours, reference, reference_name, goal, met

(``reference``/``goal``/``met`` may be None).  The table shows ours next to the
reference and their ratio; all rows go to ``bench-results/bench-<UTC time>.json``
and ``bench-results/latest.json``, with the run's facts (date, commit, machine,
total time) under ``meta``.

Every run that is not ``--quick`` then merges its figures into ``docs/benchmarks.json``
and rewrites ``docs/benchmarks.md`` (tools/bench_report.py): the sections of the
benchmarks it ran are replaced, each with this run's date, commit and settings, and
the others stay as they were, so ``-k NAME`` refreshes one benchmark that takes
hours without dropping the rest.  A ``--quick`` run (a smoke run) leaves both alone
unless given ``--report``; ``--no-report`` leaves them alone for any run.  The
settings recorded are the ``CHEFBOT_*`` environment variables of the run (e.g.
``CHEFBOT_FLEET_SEEDS``).

Usage:  python tools/bench.py [--quick] [-k SUBSTRING] [--report | --no-report]
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

from bench_report import REPORT, STORE, collect_meta, write_report  # tools/ is this script's directory
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
    report = ap.add_mutually_exclusive_group()
    report.add_argument("--report", action="store_true",
                        help=f"merge into {STORE.relative_to(ROOT)} and {REPORT.relative_to(ROOT)} "
                             "even for a --quick run")
    report.add_argument("--no-report", action="store_true", help="leave both alone")
    args = ap.parse_args()

    files = [p for p in discover() if not args.pattern or args.pattern in str(p)]
    if not files:
        print("[bench] no benchmarks found")
        return 1
    rows: list[dict] = []
    errors = 0
    failed: list[str] = []
    sources: dict[str, str] = {}
    file_seconds: dict[str, float] = {}
    meta = collect_meta()  # the commit and tree state the run starts from
    meta["settings"] = {k: v for k, v in sorted(os.environ.items()) if k.startswith("CHEFBOT_")}
    t0 = time.monotonic()
    for path in files:
        rel = path.relative_to(ROOT)
        print(f"[bench] {rel} ...", flush=True)
        t_file = time.monotonic()
        try:
            got = load(path).run(quick=args.quick)
        except Exception:  # noqa: BLE001 - one broken benchmark must not hide the others' figures
            traceback.print_exc()
            errors += 1
            failed.append(str(rel))
            continue
        finally:
            file_seconds[str(rel)] = round(time.monotonic() - t_file, 1)
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
                file_seconds=file_seconds, load_end=round(os.getloadavg()[0], 2))
    doc = {"time_utc": stamp, "host": platform.node(), "python": platform.python_version(),
           "quick": args.quick, "seconds": seconds, "meta": meta, "rows": rows}
    for name in (f"bench-{stamp}.json", "latest.json"):
        (OUT / name).write_text(json.dumps(doc, indent=2) + "\n")
    print(f"\n[bench] {len(rows)} figures from {len(files)} benchmarks in {doc['seconds']} s; "
          f"JSON: {(OUT / 'latest.json').relative_to(ROOT)}; {errors} errors")
    if args.no_report or (args.quick and not args.report):
        print(f"[bench] {REPORT.relative_to(ROOT)} left as it is "
              f"({'--no-report' if args.no_report else 'quick run; --report merges it'})")
    else:
        existing = {str(p.relative_to(ROOT)) for p in discover()}
        try:
            page = write_report(doc, existing_sources=existing)
        except ValueError as exc:   # a corrupt store: say so, keep it for the user to look at
            print(f"[bench] {STORE.relative_to(ROOT)} not updated: {exc}")
            return 1
        print(f"[bench] merged into {STORE.relative_to(ROOT)}; report: {page.relative_to(ROOT)}")
    return 1 if errors else 0


if __name__ == "__main__":
    stop_on_sigterm()
    sys.exit(main())
