#!/usr/bin/env python3
"""docs/benchmarks.md (and the figures it shows, docs/benchmarks.json) from the JSON tools/bench.py writes.

The page has one section per benchmark, each with the figures of the last run that measured it and that
run's facts (date, commit, machine, wall time, settings): ``merge(store, doc)`` replaces the sections a
run measured and keeps the others, so a benchmark that takes hours can be rerun alone.  ``merge`` and
``render_store`` are pure; rows are as tools/bench.py collects them (bench, case, metric, ours,
reference, reference_name, goal, met), the run's facts as :func:`collect_meta` takes them.

    python tools/bench_report.py                                  # rebuild the page from the store
    python tools/bench_report.py bench-results/bench-X.json ...   # merge stored runs first
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import platform
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
REPORT = ROOT / "docs" / "benchmarks.md"


# ----------------------------------------------------------------- formatting
def fmt_value(x: object) -> str:
    """One figure for a table cell: None -> "-", floats to 4 significant digits,
    magnitudes from 1000 on as integers with a space every three digits."""
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, int):
        return f"{x:,}".replace(",", " ")
    if isinstance(x, float):
        if math.isnan(x):
            return "NaN"
        if math.isinf(x):
            return "inf" if x > 0 else "-inf"
        if x == 0:
            return "0"
        if abs(x) >= 1000:
            return f"{round(x):,}".replace(",", " ")
        return f"{x:.4g}"
    return str(x)


def fmt_met(met: object) -> str:
    """yes / NO / - (no goal, or not measured)."""
    return "-" if met is None else ("yes" if met else "NO")


def fmt_duration(seconds: float | None) -> str:
    """``45.2 s``, ``31 min 12 s``, ``1 h 02 min``."""
    if seconds is None:
        return "unknown"
    s = float(seconds)
    if s < 60:
        return f"{s:.1f} s"
    m, sec = divmod(round(s), 60)
    if m < 60:
        return f"{m} min {sec:02d} s"
    h, m = divmod(m, 60)
    return f"{h} h {m:02d} min"


def _cell(text: object) -> str:
    """Table cell text: no pipes or line breaks that would break the row."""
    return str(text).replace("|", "\\|").replace("\r", " ").replace("\n", " ").strip() or "-"


def _memory(meta: dict) -> str:
    b = meta.get("memory_bytes")
    return f"{b / 2**30:.1f} GiB memory" if isinstance(b, (int, float)) else "memory unknown"


def _load(meta: dict) -> str:
    """The machine's 1-min load average at the run's start and end: figures under load are slower."""
    start, end = meta.get("load_start"), meta.get("load_end")
    if start is None and end is None:
        return "unknown"
    def one(x: object) -> str:
        return fmt_value(x) if x is not None else "?"
    return f"{one(start)} at the start, {one(end)} at the end"


# ----------------------------------------------------------------- the store: one run per section
# docs/benchmarks.json keeps every bench's latest figures with the facts of the run that measured them, so
# that a bench that takes hours (the fleet scenarios) can be rerun alone without dropping the others' figures.
STORE = ROOT / "docs" / "benchmarks.json"
STORE_FORMAT = 1
RUN_KEYS = ("date_utc", "commit", "dirty", "cpu", "cores", "memory_bytes", "os", "kernel", "python", "host",
            "quick", "pattern", "settings", "load_start", "load_end")


def empty_store() -> dict:
    return {"format": STORE_FORMAT, "benches": []}


def check_store(store: object) -> dict:
    """``store`` if it has the shape :func:`merge` writes; ValueError naming what is wrong otherwise (a
    hand-edited or truncated file must not silently become an empty page)."""
    if not isinstance(store, dict) or store.get("format") != STORE_FORMAT or not isinstance(
            store.get("benches"), list):
        raise ValueError(f"not a benchmark store of format {STORE_FORMAT} (a dict with 'format' and 'benches')")
    for i, sec in enumerate(store["benches"]):
        if not isinstance(sec, dict) or not isinstance(sec.get("name"), str) or not isinstance(
                sec.get("rows"), list) or not isinstance(sec.get("run"), dict):
            raise ValueError(f"benches[{i}]: a section needs 'name' (text), 'run' (dict) and 'rows' (list)")
    return store


def merge(store: dict, doc: dict, existing_sources: set[str] | None = None) -> dict:
    """A new store: ``store`` with the benches measured in ``doc`` (a tools/bench.py JSON) replaced by
    their new rows and this run's facts; every other section kept as it was.  A bench file that failed
    in this run keeps its earlier figures, marked with the failed run.  ``existing_sources`` (the bench
    files the workspace has now), if given, drops sections whose file is gone.  Sections are ordered by
    source file, then as the bench produced them.  Pure: the inputs are not changed."""
    meta = meta_from_doc(doc)
    sources = meta.get("sources") or {}
    seconds = meta.get("file_seconds") or {}
    run = {k: meta.get(k) for k in RUN_KEYS if meta.get(k) is not None}
    new: dict[str, dict] = {}
    for r in doc.get("rows") or []:
        name = str(r.get("bench"))
        if name not in new:
            src = sources.get(name)
            new[name] = {"name": name, "source": src,
                         "run": dict(run, seconds=seconds.get(src)) if src in seconds else dict(run),
                         "rows": []}
        new[name]["rows"].append(dict(r))
    failed = set(meta.get("failed") or [])
    out, seen = [], set()
    for sec in check_store(store)["benches"]:
        if sec["name"] in new:
            out.append(new[sec["name"]])
        else:
            sec = json.loads(json.dumps(sec))
            if sec.get("source") in failed:
                sec["failed_run"] = {k: run[k] for k in ("date_utc", "commit") if k in run}
            if existing_sources is None or sec.get("source") is None or sec["source"] in existing_sources:
                out.append(sec)
        seen.add(sec["name"])
    out += [sec for name, sec in new.items() if name not in seen]
    order = {name: i for i, name in enumerate(s["name"] for s in out)}
    out.sort(key=lambda s: (s.get("source") or "~", order[s["name"]]))
    return {"format": STORE_FORMAT, "benches": out}


def load_store(path: Path = STORE) -> dict:
    """The store at ``path``; an empty one if the file does not exist; ValueError if it is corrupt."""
    if not path.exists():
        return empty_store()
    try:
        return check_store(json.loads(path.read_text()))
    except json.JSONDecodeError as exc:
        raise ValueError(f"{path}: not JSON ({exc})") from exc
    except ValueError as exc:
        raise ValueError(f"{path}: {exc}") from exc


def save_store(store: dict, path: Path = STORE) -> Path:
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(path.suffix + ".tmp")
    tmp.write_text(json.dumps(check_store(store), indent=1) + "\n")
    tmp.replace(path)   # never half a file
    return path


# ----------------------------------------------------------------- report
def _commit(run: dict) -> str:
    commit = run.get("commit") or "unknown"
    return commit + (" + uncommitted changes" if run.get("dirty") else "")


def _machine(run: dict) -> str:
    cores = run.get("cores")
    return ", ".join([run.get("cpu") or "CPU unknown", f"{cores} cores" if cores else "cores unknown",
                      _memory(run)])


def _run_kind(run: dict) -> str:
    kind = "full run"
    if run.get("quick"):
        kind = "quick run (`--quick`: fewer repetitions, smaller cases)"
    if run.get("pattern"):
        kind = ("quick run" if run.get("quick") else "run") + f" of `-k {run['pattern']}`"
    settings = run.get("settings") or {}
    if settings:
        kind += ", " + ", ".join(f"`{k}={v}`" for k, v in sorted(settings.items()))
    return kind


def render_store(store: dict) -> str:
    """The Markdown page from a store: a header, a table of the runs that measured the sections (date,
    commit, wall time, how it was run), then one section per bench with a table
    case / metric / ours / goal / reference / met.  Pure."""
    benches = check_store(store)["benches"]
    rows = [r for sec in benches for r in sec["rows"]]
    out = ["# Benchmarks", "",
           "Generated by `make bench` (`tools/bench.py`) from [benchmarks.json](benchmarks.json); do not edit "
           "by hand. Each section holds the figures of the last run of its benchmark, with that run's date and "
           "commit: `make bench` reruns all of them, `python tools/bench.py -k NAME` only those whose file "
           "matches (the other sections stay as they were), `--quick` (a smoke run) changes nothing unless "
           "given `--report`. `python tools/bench_report.py` rebuilds this page from the JSON; "
           "`python tools/bench_report.py bench-results/X.json` merges a stored run into it first. "
           "The fleet soak (`make soak`, hours of orders with faults) has its own page: [soak.md](soak.md)."]
    machines = sorted({_machine(sec["run"]) for sec in benches})
    systems = sorted({f"{sec['run'].get('os') or 'unknown'}, kernel {sec['run'].get('kernel') or 'unknown'}, "
                      f"Python {sec['run'].get('python') or 'unknown'}" for sec in benches})
    if machines:
        out += ["", "| | |", "|---|---|",
                f"| Machine | {_cell('; '.join(machines))} |",
                f"| OS | {_cell('; '.join(systems))} |"]
    met = [r.get("met") for r in rows]
    n_yes, n_no = met.count(True), met.count(False)
    out += ["", f"{len(rows)} figures from {len(benches)} benchmarks. Goal met: {n_yes}; "
                f"not met (NO): {n_no}; no goal (-): {len(rows) - n_yes - n_no}.",
            "", "Columns: *ours* is the figure measured here; *reference* is what it is compared with "
            "(its source in brackets); *met* says whether *ours* reaches the *goal*."]
    failed = [sec for sec in benches if sec.get("failed_run")]
    if failed:
        out += ["", "**Benchmarks whose last run failed** (their sections show the run before):", ""]
        out += [f"* `{_cell(sec.get('source') or sec['name'])}` ({_cell(sec['failed_run'].get('date_utc'))}, "
                f"{_cell(sec['failed_run'].get('commit'))})" for sec in failed]
    if benches:
        out += ["", "| benchmark | measured (UTC) | commit | wall time | run | load (1 min), start / end |",
                "|---|---|---|--:|---|---|"]
        out += ["| " + " | ".join(_cell(c) for c in (
            f"[{sec['name']}](#{_anchor(sec['name'])})", sec["run"].get("date_utc") or "unknown",
            _commit(sec["run"]), fmt_duration(sec["run"].get("seconds")), _run_kind(sec["run"]),
            _load(sec["run"]))) + " |" for sec in benches]

    for sec in benches:
        run = sec["run"]
        out += ["", f"## {sec['name']}", ""]
        where = f"Source: `{sec['source']}`. " if sec.get("source") else ""
        took = f"; {fmt_duration(run['seconds'])}" if run.get("seconds") is not None else ""
        out += [f"{where}Measured {run.get('date_utc') or 'unknown'} UTC at {_commit(run)} "
                f"({_run_kind(run)}{took}).", ""]
        out += ["| case | metric | ours | goal | reference | met |", "|---|---|--:|---|---|:-:|"]
        for r in sec["rows"]:
            ref = fmt_value(r.get("reference"))
            if r.get("reference_name"):
                ref = f"{ref} ({r['reference_name']})" if r.get("reference") is not None else str(r["reference_name"])
            out.append("| " + " | ".join(_cell(c) for c in (
                r.get("case"), r.get("metric"), fmt_value(r.get("ours")), r.get("goal") or "-", ref,
                fmt_met(r.get("met")))) + " |")
    return "\n".join(out) + "\n"


def render_report(rows: list[dict], meta: dict) -> str:
    """The page of one run alone (its rows and facts, no earlier sections)."""
    return render_store(merge(empty_store(), {"meta": meta, "rows": rows}))


def _anchor(title: str) -> str:
    """GitHub's heading anchor: lower case, punctuation dropped, spaces to dashes."""
    keep = "".join(c for c in title.lower() if c.isalnum() or c in " -_")
    return keep.replace(" ", "-")


# ----------------------------------------------------------------- run facts (not pure)
def _git(*args: str) -> str | None:
    try:
        res = subprocess.run(["git", *args], cwd=ROOT, capture_output=True, text=True, timeout=30, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return res.stdout.strip() if res.returncode == 0 else None


def _cpu_model() -> str:
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.lower().startswith(("model name", "hardware", "cpu model")):
                return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or platform.machine() or "unknown"


def _memory_bytes() -> int | None:
    try:
        for line in Path("/proc/meminfo").read_text().splitlines():
            if line.startswith("MemTotal:"):
                return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        pass
    return None


def _os_name() -> str:
    try:
        for line in Path("/etc/os-release").read_text().splitlines():
            if line.startswith("PRETTY_NAME="):
                return line.split("=", 1)[1].strip().strip('"')
    except OSError:
        pass
    return platform.system()


def collect_meta() -> dict:
    """Facts of this machine and checkout, taken at the start of a run."""
    status = _git("status", "--porcelain")
    return {"date_utc": dt.datetime.now(dt.UTC).strftime("%Y-%m-%d %H:%M"),
            "commit": _git("rev-parse", "--short", "HEAD"),
            "dirty": bool(status) if status is not None else None,
            "cpu": _cpu_model(), "cores": os.cpu_count(), "memory_bytes": _memory_bytes(),
            "os": _os_name(), "python": platform.python_version(), "kernel": platform.release(),
            "host": platform.node(), "load_start": round(os.getloadavg()[0], 2)}


def meta_from_doc(doc: dict) -> dict:
    """The report's meta from a bench JSON; older files without ``meta`` give what they have."""
    meta = dict(doc.get("meta") or {})
    if meta.get("date_utc"):
        meta["date_utc"] = str(meta["date_utc"]).removesuffix(" UTC")   # the column says UTC already
    elif doc.get("time_utc"):
        try:
            t = dt.datetime.strptime(doc["time_utc"], "%Y%m%dT%H%M%SZ")
            meta["date_utc"] = t.strftime("%Y-%m-%d %H:%M")
        except ValueError:
            meta["date_utc"] = doc["time_utc"]
    for key in ("python", "seconds", "quick", "pattern", "failed", "sources"):
        if key not in meta and key in doc:
            meta[key] = doc[key]
    return meta


def write_report(doc: dict | None, out: Path = REPORT, store_path: Path = STORE,
                 existing_sources: set[str] | None = None) -> Path:
    """Merge ``doc`` (a bench JSON; None: nothing new) into the store at ``store_path``, save it, and
    render the page into ``out``."""
    store = load_store(store_path)
    if doc is not None:
        store = merge(store, doc, existing_sources)
        save_store(store, store_path)
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_text(render_store(store))
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("json", type=Path, nargs="*", help="bench-results/*.json files to merge, oldest first")
    ap.add_argument("-o", "--output", type=Path, default=REPORT, help="Markdown file (default docs/benchmarks.md)")
    ap.add_argument("--store", type=Path, default=STORE, help="the figures kept (default docs/benchmarks.json)")
    args = ap.parse_args()
    try:
        docs = [json.loads(p.read_text()) for p in args.json]
        out = args.output
        for doc in docs or [None]:
            out = write_report(doc, args.output, args.store)
        store = load_store(args.store)
    except (OSError, ValueError) as exc:   # json.JSONDecodeError is a ValueError
        print(f"[bench_report] {exc}", file=sys.stderr)
        return 1
    print(f"[bench_report] {sum(len(s['rows']) for s in store['benches'])} rows in "
          f"{len(store['benches'])} sections -> {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
