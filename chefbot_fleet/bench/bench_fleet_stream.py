"""The order queue with the whole stack: one seeded stream of orders served by 1, 2 and 3 simulated
robots, by our planner and by the nearest-idle baseline (issue 33's figures).

Each run is ``tools/fleet_demo.py`` (what ``make demo ROBOTS=N`` runs): the hotel in pybullet, every
robot's amcl and move_base, the traffic rule and the dispatcher with the policy under test, the same
seeded Poisson stream of ``CHEFBOT_STREAM_ORDERS`` orders (default 30; quick: 6) of one or two tables
placed on ``/fleet/deliver`` at their sim times, one order per ``CHEFBOT_STREAM_EVERY`` s on average
(default: a sixth of one robot's mean single-order trip over our planner's paths, about 13 s —
bench_dispatch's fastest stream, which keeps three robots busy: at a third of it, 25 s, the 30
orders' arrivals, not the robots, set three robots' makespan, and planning alone puts their
throughput at 2.0x one robot's; at a sixth, 2.8x).  Per run, from the
simulator's ground truth (a test oracle): orders served (within 0.05 m of their table), orders per
hour, the waits (order placed → robot standing at its last table: mean, median, 95th percentile),
makespan, km driven, bumper contacts, orders lost (never final) or served twice, and sim seconds per
wall second.  Goals: 3 robots ≥ 2.5× the throughput of one; our mean wait ≤ 0.8× the baseline's;
0 contacts; 0 orders lost or duplicated.  Six runs of some 15–40 min of sim time each at real time:
about 2–3 h (quick: two runs, about 10 min).  ``CHEFBOT_STREAM_SEED`` (default 0) picks the stream.
Each run's logs stay in build/bench_fleet_stream/ROBOTS_POLICY/, with its settings (settings.json:
robots, policy, orders, gap, seed, commit).  ``CHEFBOT_STREAM_REUSE=1`` takes a kept run that
ended every order (none lost) and whose settings are this run's instead of running it again (an interrupted
bench resumes, or runs split across machines are put together); each reused run is named with its
commit on the bench's output; ``CHEFBOT_STREAM_KEPT_ONLY=1`` runs nothing and reports the kept runs
(those missing are left out of the rows).  ``CHEFBOT_STREAM_FLEETS`` (default "1,2,3") picks the fleet
sizes.
"""
from __future__ import annotations

import importlib.util
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
POLICIES = ("insertion", "nearest_idle")
BASELINE = "nearest idle, one order per trip"
METRICS = (("orders per hour", "orders_per_hour"), ("wait s, mean", "wait_mean_s"),
           ("wait s, median", "wait_median_s"), ("wait s, 95th percentile", "wait_p95_s"),
           ("makespan s", "makespan_s"), ("km driven", "km"), ("sim s per wall s", "sim_per_wall"))
RUN_TIMEOUT_S = 4 * 3600.0      # one run's wall-time bound (against hangs only)
SETTINGS = ("robots", "policy", "orders", "every", "seed")     # what makes two runs the same run


def run_settings(robots: int, policy: str, orders: int, every: float, seed: int) -> dict:
    """A run's settings as kept in its settings.json (the gap to the millisecond fleet_demo is given)."""
    return {"robots": robots, "policy": policy, "orders": orders, "every": round(every, 3), "seed": seed}


def kept_run(run_dir: Path, settings: dict) -> dict | None:
    """The summary of the run kept in ``run_dir`` when it was made with ``settings`` (its
    settings.json) and finished with every order ended (its fleet.json: none lost; a run that gave up
    is run again), plus ``commit`` and ``exit`` None (not kept); else None."""
    try:
        kept = json.loads((run_dir / "settings.json").read_text())
        summary = json.loads((run_dir / "fleet.json").read_text())["summary"]
    except (OSError, ValueError, KeyError, TypeError):
        return None
    if not isinstance(kept, dict) or any(kept.get(k) != settings[k] for k in SETTINGS if k != "every"):
        return None
    if not isinstance(kept.get("every"), (int, float)) or abs(kept["every"] - settings["every"]) > 5e-4:
        return None                 # another gap (fleet_demo is given it to the millisecond)
    if not isinstance(summary, dict) or summary.get("lost") != 0:
        return None
    return dict(summary, exit=None, commit=kept.get("commit"))


def _head() -> str | None:
    try:
        return subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                              text=True, timeout=10).stdout.strip() or None
    except (OSError, subprocess.SubprocessError):
        return None


def stream_gap() -> float:
    """bench_dispatch's fastest stream: a sixth of one robot's mean single-order trip (load, drive,
    serve, back) over our planner's hotel paths."""
    spec = importlib.util.spec_from_file_location("chefbot_bench_dispatch_site", Path(__file__).with_name(
        "bench_dispatch.py"))
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    site, names = mod.hotel_site()
    return mod.rates(mod.single_order_trip_s(site, [n for n in names if n != site.kitchen]))[-1][0]


def run_stream(robots: int, policy: str, orders: int, every: float, seed: int) -> dict:
    """One full-stack run of the stream; fleet_demo's summary (its fleet.json) plus ``exit``.  With
    ``CHEFBOT_STREAM_REUSE=1``, the kept run of the same settings if it finished."""
    tmp = ROOT / "build" / "bench_fleet_stream" / f"{robots}_{policy}"      # kept: the run's logs
    settings = run_settings(robots, policy, orders, every, seed)
    if os.environ.get("CHEFBOT_STREAM_REUSE", "") not in ("", "0"):
        kept = kept_run(tmp, settings)
        if kept is not None:
            print(f"[bench] fleet_stream {robots} robot(s), {policy}: the kept run of {kept['commit'] or '?'} "
                  f"({tmp}): delivered {kept.get('delivered')}/{orders}", flush=True)
            return kept
    shutil.rmtree(tmp, ignore_errors=True)
    tmp.mkdir(parents=True)
    (tmp / "settings.json").write_text(json.dumps(dict(settings, commit=_head()), indent=1) + "\n")
    env = dict(os.environ, CHEFBOT_DEMO_ROBOTS=str(robots), CHEFBOT_DEMO_POLICY=policy,
               CHEFBOT_DEMO_ORDERS=str(orders), CHEFBOT_DEMO_ORDER_EVERY=f"{every:.3f}",
               CHEFBOT_DEMO_SEED=str(seed), CHEFBOT_DEMO_DIR=str(tmp), CHEFBOT_DEMO_GUI="0", CHEFBOT_DEMO_RTF="1.0")
    proc = subprocess.Popen([sys.executable, str(ROOT / "tools" / "fleet_demo.py")], env=env,
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        out, _ = proc.communicate(timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        proc.terminate()            # fleet_demo stops its process groups on SIGTERM
        out, _ = proc.communicate()
    code = proc.returncode
    for line in out.splitlines():
        if line.startswith("[demo] delivered") or "ERROR" in line:
            print(f"[bench] fleet_stream {robots} robot(s), {policy}: {line[7:]}", flush=True)
    path = tmp / "fleet.json"
    if not path.is_file():          # the run died before its summary: show why, count every order lost
        tail = "\n".join(out.splitlines()[-20:])
        print(f"[bench] fleet_stream {robots} robot(s), {policy}: no summary (exit {code}); "
              f"its last lines:\n{tail}", flush=True)
        return {"exit": code, "orders": orders, "delivered": 0, "lost": orders, "served_twice": 0,
                "contacts": 0}
    summary = json.loads(path.read_text())["summary"]
    summary["exit"] = code
    return summary


def stream_rows(results: dict[tuple[int, str], dict], orders: int, every: float, seed: int) -> list[dict]:
    """The bench's rows from each (robots, policy) run's summary (pure)."""
    rows = []
    for robots in sorted({r for r, _ in results}):
        ours, base = results.get((robots, "insertion")), results.get((robots, "nearest_idle"))
        if ours is None:
            continue
        case = (f"hotel, full stack, {orders} orders of 1-2 tables, one per {every:.0f} s (seed {seed}), "
                f"{robots} robot{'s' if robots > 1 else ''}")
        for name, key in METRICS:
            mine = ours.get(key)
            ref = base.get(key) if base else None
            goal = met = None
            if key == "wait_mean_s" and mine is not None and ref is not None:
                goal, met = "<= 0.8x baseline", bool(mine <= 0.8 * ref)
            rows.append({"bench": "fleet_stream", "case": case, "metric": name,
                         "ours": None if mine is None else float(mine),
                         "reference": None if ref is None else float(ref),
                         "reference_name": BASELINE if ref is not None else None, "goal": goal, "met": met})
        served = int(ours.get("delivered", 0))
        rows.append({"bench": "fleet_stream", "case": case, "metric": "orders served at their tables",
                     "ours": served, "reference": orders, "reference_name": "orders placed",
                     "goal": f"{orders}/{orders}", "met": served == orders})
        for name, key in (("bumper contacts", "contacts"), ("orders lost or served twice", None)):
            runs = [r for r in (ours, base) if r is not None]
            value = sum(int(r.get("lost", 0)) + int(r.get("served_twice", 0)) if key is None
                        else int(r.get(key, 0)) for r in runs)
            rows.append({"bench": "fleet_stream", "case": case + (", both policies" if base else ""),
                         "metric": name, "ours": value, "reference": None, "reference_name": None, "goal": "0",
                         "met": value == 0})
    one, three = results.get((1, "insertion")), results.get((3, "insertion"))
    if one and three and one.get("orders_per_hour") and three.get("orders_per_hour") is not None:
        ratio = float(three["orders_per_hour"] / one["orders_per_hour"])
        rows.append({"bench": "fleet_stream", "case": "hotel, full stack, throughput of 3 robots / 1 robot",
                     "metric": "ratio", "ours": ratio, "reference": None, "reference_name": None,
                     "goal": ">= 2.5", "met": ratio >= 2.5})
    return rows


def fleet_sizes(raw: str) -> tuple[int, ...]:
    """``CHEFBOT_STREAM_FLEETS``: the fleet sizes to run, e.g. "1,3" (default: 1, 2 and 3 robots)."""
    try:
        sizes = tuple(sorted({int(x) for x in raw.replace(",", " ").split()})) or (1, 2, 3)
    except ValueError:
        raise ValueError(f"CHEFBOT_STREAM_FLEETS must be robot counts such as '1,3', got {raw!r}") from None
    if sizes[0] < 1:
        raise ValueError(f"CHEFBOT_STREAM_FLEETS: a fleet has at least one robot, got {raw!r}")
    return sizes


def run(quick: bool = False) -> list[dict]:
    orders = 6 if quick else int(os.environ.get("CHEFBOT_STREAM_ORDERS", "30"))
    every = float(os.environ.get("CHEFBOT_STREAM_EVERY", "0") or 0) or stream_gap()
    seed = int(os.environ.get("CHEFBOT_STREAM_SEED", "0"))
    fleets = (1, 3) if quick else fleet_sizes(os.environ.get("CHEFBOT_STREAM_FLEETS", ""))
    policies = ("insertion",) if quick else POLICIES
    if os.environ.get("CHEFBOT_STREAM_KEPT_ONLY", "") not in ("", "0"):
        results = {}
        for n in fleets:
            for p in policies:
                kept = kept_run(ROOT / "build" / "bench_fleet_stream" / f"{n}_{p}",
                                run_settings(n, p, orders, every, seed))
                print(f"[bench] fleet_stream {n} robot(s), {p}: " +
                      (f"the kept run of {kept['commit'] or '?'}" if kept else "no kept run: left out"), flush=True)
                if kept:
                    results[(n, p)] = kept
    else:
        results = {(n, p): run_stream(n, p, orders, every, seed) for n in fleets for p in policies}
    return stream_rows(results, orders, every, seed)


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(row)
