#!/usr/bin/env python3
"""`make soak [HOURS=2] [ROBOTS=3] [SEED=0]`: the fleet soak test (issue 33).

HOURS of sim time of a seeded Poisson stream of orders (one or two hotel tables each) served by
ROBOTS robots, each part of the fleet started as it would run on its own machine, all on one host
and one private master: the world (``chefbot_sim fleet_sim.launch``), the server
(``chefbot_fleet fleet_server.launch respawn:=true sim_time:=true``: map_server, traffic, the
dispatcher) and one ``chefbot_sim fleet_robot.launch robot:=NAME`` per robot, each its own roslaunch.
Faults at fixed fractions of the run: one robot's whole stack (its roslaunch and every node of it)
killed with SIGKILL at 25 % and again at 60 %, started again after ``--downtime`` s of sim time
(its fleet_member gives amcl the pose it saved before dying: chefbot_fleet README, fleet_member);
the dispatcher killed at 45 % (``rosnode kill``; roslaunch's respawn starts it again); batteries
run down and charge throughout (the world gets a small, half-charged pack and a faster charger
through ``sim_params:=``, so each robot goes to charge within the run, whatever its length).

Judged at the end (exit code 1 when a check fails): every order placed ends ``served``, or
``failed``/``cancelled`` with a reason, within the drain period (``--drain`` s of sim time); none
lost (never final), none served twice nor changed after its final state (the state sequences seen on
``/fleet/orders``); every served robot stood at a table (ground truth, the judge's only use of it);
every fault recovered (the robot back in service, the dispatcher publishing again); at least one
battery charge completed; the RSS of every node (``/proc/PID/status``, each node's pid from the
master's ``lookupNode`` and its ``getPid``) sampled every ``--sample-every`` s of wall time and its
growth fitted per hour (after a warm-up; judged only when the fit spans ``MIN_FIT_SPAN_S`` or more);
every node's pid unchanged unless the test killed it (a pid that changed otherwise, or a node that
vanished, is "restarted by something else"). Bumper contacts are counted and reported.

Output: ``bench-results/soak-<UTC time>.json`` and ``bench-results/soak-latest.json``; the page
``docs/soak.md`` only from a run of at least ``REPORT_MIN_HOURS`` h of sim time, or with
``--report`` (the page then says how long the run was), so a short check never replaces the report
of a real soak.  ``python tools/fleet_soak.py --render bench-results/soak-latest.json`` rebuilds the
page from a stored JSON.  Logs: build/soak/.

Usage:  python tools/fleet_soak.py [--hours 2] [--robots 3] [--seed 0] [--order-every 30] [--report]
"""
from __future__ import annotations

import argparse
import datetime as dt
import json
import math
import os
import random
import signal
import subprocess
import sys
import threading
import time
import xmlrpc.client
from pathlib import Path

import numpy as np
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_report import collect_meta, fmt_duration
from fleet_demo import FINAL, XY_TOL, FleetDemoError, Watch, load_site, order_stream, site_files, summarise
from procs import ProcessGroup, free_port, group_tree, stop_on_sigterm, stop_tracked

ROOT = Path(__file__).resolve().parent.parent
LOG_DIR = ROOT / "build" / "soak"
OUT = ROOT / "bench-results"
REPORT = ROOT / "docs" / "soak.md"
REPORT_MIN_HOURS = 1.0                # a shorter run writes docs/soak.md only with --report
ROBOT_KILLS = (0.25, 0.60)            # fractions of the run: the same robot's stack killed twice
DISPATCHER_KILL = 0.45                # fraction of the run: the dispatcher killed once
STARTUP_TIMEOUT_S = 300.0             # wall s for the world, the server and every stack to come up
STEP_TIMEOUT_S = 300.0                # wall s for any one wait of the run (a recovery, a kill)
ACCEPT_TIMEOUT_S = 30.0               # wall s for the dispatcher to accept an order (its id)
MIN_FIT_SPAN_S = 1800.0               # wall s: a shorter memory fit is reported, not judged
MAX_GROWTH_MB_H = 10.0                # MB/h: a node growing faster fails "memory flat"
SERVED_AWAY_M = 0.25                  # m: a robot served further than this from every table of its order
IN_SERVICE = ("idle", "to_kitchen", "loading", "delivering", "serving", "parking")
LOCALIZED_M = 0.3                     # m: a restarted robot's own pose this near the truth is localized
LOCALIZE_WINDOW_S = 90.0              # sim s after its return to service for that
OPEN_FLOOR_M = 1.5                    # m: a robot is killed this far from the kitchen and every table, if it can be


class SoakError(RuntimeError):
    """The run could not go on (a part that did not come up, a wait that ran out)."""


def say(msg: str) -> None:
    print(f"[soak] {msg}", flush=True)


# ----------------------------------------------------------------- pure parts (tests/unit/test_fleet_soak.py)
def fault_schedule(sim_s: float, names: list[str], seed: int) -> list[dict]:
    """The faults of a run of ``sim_s`` s: one robot (seeded choice of ``names``) killed at each of
    ROBOT_KILLS, the dispatcher at DISPATCHER_KILL; sorted by time ``at`` (sim s from the stream's start)."""
    if not names or not sim_s > 0:
        raise ValueError("a fault schedule needs robots and a run length > 0")
    victim = random.Random(seed).choice(names)
    faults = [{"kind": "robot", "target": victim, "at": round(f * sim_s, 1)} for f in ROBOT_KILLS]
    faults.append({"kind": "dispatcher", "target": "/fleet/dispatcher", "at": round(DISPATCHER_KILL * sim_s, 1)})
    return sorted(faults, key=lambda f: f["at"])


START_SOCS = (0.4, 0.55, 0.7)    # the robots' start charges, in turn: they go to charge one after another


def sim_battery(hours: float, names: list[str]) -> dict:
    """chefbot_sim_node battery params that make every robot go to charge within a run of ``hours``:
    a pack of 2 Ah per hour of run, at least 1 Ah (the dispatcher's last 25 % must carry a robot through
    the trip it is on: ~200 s at ~3.5 A is 0.2 Ah; a 0.3 Ah pack ran flat on the way), each robot
    starting at its own charge (``~robot_options``: 40, 55, 70 %, in turn; at ~3 A a robot of a 2 h
    run reaches 25 % after a tenth, a fifth, three tenths of it: with one start for all, every robot
    went to charge at once and the queue waited) and a 10 A charger (25 -> 90 % in about a sixth of a
    2 h run)."""
    return {"battery_capacity_ah": round(max(1.0, 2.0 * hours), 3), "battery_initial_soc": START_SOCS[0],
            "charge_current": 10.0,
            "robot_options": {n: {"battery_initial_soc": START_SOCS[k % len(START_SOCS)]}
                              for k, n in enumerate(names)}}


def start_socs(battery: dict) -> str:
    """The robots' start charges of :func:`sim_battery`'s params, for the report (``40%`` or
    ``chefbot1 40%, chefbot2 55%``)."""
    per = battery.get("robot_options") or {}
    if not per:
        return f"{battery['battery_initial_soc']:.0%}"
    return ", ".join(f"{n} {o.get('battery_initial_soc', battery['battery_initial_soc']):.0%}"
                     for n, o in per.items())


def record_states(histories: dict[str, list[tuple[str, str, float]]], orders, t: float) -> None:
    """Append each order's state to its history when it differs from the last one seen:
    ``orders`` is (id, state, reason) triples of one /fleet/orders message received at ``t``."""
    for oid, state, reason in orders:
        seq = histories.setdefault(oid, [])
        if not seq or seq[-1][0] != state:
            seq.append((state, reason, t))


def judge_orders(placed: dict[str, float], histories: dict[str, list[tuple[str, str, float]]]) -> dict:
    """Every placed order's end from its state history: ``served``, ``failed``/``cancelled`` (the reason
    counted; one without a reason is a fault of the queue), ``lost`` (never final), ``duplicated``
    (served more than once, or any state after its first final one)."""
    out = {"placed": len(placed), "served": 0, "failed": 0, "cancelled": 0, "lost": [], "duplicated": [],
           "no_reason": [], "reasons": {}, "final_s": {}}
    for oid in sorted(placed, key=lambda i: placed[i]):
        seq = histories.get(oid, [])
        finals = [k for k, (state, _, _) in enumerate(seq) if state in FINAL]
        if not finals:
            out["lost"].append(oid)
            continue
        first = finals[0]
        state, reason, t = seq[first]
        if len(seq) > first + 1 or sum(1 for s, _, _ in seq if s == "served") > 1:
            out["duplicated"].append(oid)
        out[state] += 1
        out["final_s"][oid] = t - placed[oid]
        if state != "served":
            if reason.strip():
                out["reasons"][reason] = out["reasons"].get(reason, 0) + 1
            else:
                out["no_reason"].append(oid)
    return out


def growth_mb_per_h(samples: list[tuple[float, float]], warmup_s: float = 0.0) -> tuple[float | None, float]:
    """Least-squares slope of RSS over time in MB per hour, from ``samples`` (wall s, bytes) after the
    first ``warmup_s`` s, and the span (s) of the samples fitted; None with fewer than 3 samples."""
    if not samples:
        return None, 0.0
    t0 = samples[0][0]
    kept = [(t, b) for t, b in samples if t - t0 >= warmup_s]
    if len(kept) < 3:
        return None, 0.0
    t = np.array([s[0] for s in kept], dtype=float)
    b = np.array([s[1] for s in kept], dtype=float)
    span = float(t[-1] - t[0])
    if span <= 0:
        return None, 0.0
    slope = np.polyfit(t - t[0], b, 1)[0]                # bytes per s
    return float(slope * 3600.0 / 1e6), span


def segments(series: list[tuple[float, int | None, float | None]]) -> list[dict]:
    """A node's samples (wall s, pid or None when not reachable, RSS bytes) cut into one run per pid:
    [{pid, first, last, samples [(t, rss)]}] in time order."""
    out: list[dict] = []
    for t, pid, rss in series:
        if pid is None:
            continue
        if not out or out[-1]["pid"] != pid:
            out.append({"pid": pid, "first": t, "last": t, "samples": []})
        out[-1]["last"] = t
        if rss is not None:
            out[-1]["samples"].append((t, rss))
    return out


def killed_by_test(node: str, kills: list[tuple[float, str]], after: float, before: float,
                   slack: float = 2.0) -> bool:
    """Whether the test killed ``node`` between two samples: a kill of a name or namespace prefix
    (``/chefbot2/`` or ``/fleet/dispatcher``) matching it at a wall time in [after - slack, before]."""
    return any(after - slack <= t <= before and (node == target or node.startswith(target))
               for t, target in kills)


def restarts_by_others(series: dict[str, list[tuple[float, int | None, float | None]]],
                       kills: list[tuple[float, str]]) -> list[dict]:
    """Every node whose pid changed without the test having killed it, or that was last seen
    unreachable (vanished) though seen before: [{node, what, at}]."""
    out = []
    for node, samples in sorted(series.items()):
        runs = segments(samples)
        for prev, cur in zip(runs, runs[1:], strict=False):
            if not killed_by_test(node, kills, prev["last"], cur["first"]):
                out.append({"node": node, "what": f"pid {prev['pid']} -> {cur['pid']}", "at": cur["first"]})
        if runs and samples[-1][1] is None:
            out.append({"node": node, "what": f"vanished (pid {runs[-1]['pid']} last seen)", "at": samples[-1][0]})
    return out


def memory_table(series: dict[str, list[tuple[float, int | None, float | None]]], warmup_s: float) -> list[dict]:
    """Per node: its RSS at the start and the end (MB), and the growth (MB/h) fitted over its longest
    run (one pid) after ``warmup_s`` s of that run, with the fit's span (s)."""
    rows = []
    for node, samples in sorted(series.items()):
        runs = [r for r in segments(samples) if r["samples"]]
        if not runs:
            rows.append({"node": node, "runs": 0, "rss_start_mb": None, "rss_end_mb": None,
                         "growth_mb_h": None, "fit_span_s": 0.0})
            continue
        longest = max(runs, key=lambda r: r["last"] - r["first"])
        growth, span = growth_mb_per_h(longest["samples"], warmup_s)
        rows.append({"node": node, "runs": len(runs), "rss_start_mb": runs[0]["samples"][0][1] / 1e6,
                     "rss_end_mb": runs[-1]["samples"][-1][1] / 1e6, "growth_mb_h": growth, "fit_span_s": span})
    return rows


def checks(doc: dict) -> list[dict]:
    """The run's pass/fail verdicts from its figures: [{check, ok, detail}]."""
    o = doc["orders"]
    mem = [r for r in doc["memory"] if r["growth_mb_h"] is not None and r["fit_span_s"] >= MIN_FIT_SPAN_S]
    growing = [f"{r['node']} {r['growth_mb_h']:+.1f} MB/h" for r in mem if r["growth_mb_h"] > MAX_GROWTH_MB_H]
    faults = doc["faults"]
    unrecovered = [f"{f['kind']} {f['target']} at {f['at']:.0f} s" for f in faults if not f.get("recovered")]
    out = [
        {"check": "every order placed was accepted", "ok": not doc["not_accepted"],
         "detail": f"{len(doc['not_accepted'])} not accepted"},
        {"check": "every order ended served, failed or cancelled", "ok": not o["lost"],
         "detail": f"lost: {', '.join(o['lost']) or 'none'}"},
        {"check": "no order served twice or changed after its end", "ok": not o["duplicated"],
         "detail": f"duplicated: {', '.join(o['duplicated']) or 'none'}"},
        {"check": "every failed or cancelled order has a reason", "ok": not o["no_reason"],
         "detail": f"without a reason: {', '.join(o['no_reason']) or 'none'}"},
        {"check": f"every served robot stood within {SERVED_AWAY_M} m of a table", "ok": not doc["served_away"],
         "detail": f"away: {', '.join(doc['served_away']) or 'none'}"},
        {"check": "every fault injected was recovered", "ok": bool(faults) and not unrecovered,
         "detail": f"{len(faults)} injected; not recovered: {', '.join(unrecovered) or 'none'}"},
        {"check": "batteries ran down and charged (a charge completed)", "ok": doc["charges_completed"] > 0,
         "detail": f"{doc['charges_completed']} charges completed"},
        {"check": f"memory flat (every node < {MAX_GROWTH_MB_H:g} MB/h; fits over >= {MIN_FIT_SPAN_S / 60:.0f} min)",
         "ok": not growing,
         "detail": (", ".join(growing) or "none growing") + f"; {len(mem)} of {len(doc['memory'])} nodes judged"},
        {"check": "no process restarted by anything but the test", "ok": not doc["restarts_by_others"],
         "detail": ", ".join(f"{r['node']}: {r['what']}" for r in doc["restarts_by_others"]) or "none"},
    ]
    return out


def _f(x: object, spec: str = ".1f") -> str:
    return "-" if x is None or (isinstance(x, float) and math.isnan(x)) else format(x, spec)


def render_report(doc: dict) -> str:
    """docs/soak.md from a soak's JSON (pure)."""
    m, o, s = doc["meta"], doc["orders"], doc["summary"]
    commit = (m.get("commit") or "unknown") + (" + uncommitted changes" if m.get("dirty") else "")
    short = doc["sim_hours"] < REPORT_MIN_HOURS
    out = ["# Fleet soak", "",
           "Generated by `make soak` (`tools/fleet_soak.py`); do not edit by hand. Only a run of at least "
           f"{REPORT_MIN_HOURS:g} h of sim time rewrites it (`--report` forces it: the page then says the run "
           "was short). "
           "`python tools/fleet_soak.py --render bench-results/soak-latest.json` rebuilds it from the stored JSON. "
           "What the soak does: chefbot_fleet README, \"The soak\". Other figures: [benchmarks.md](benchmarks.md).", ""]
    if short:
        out += [f"**A short check ({doc['sim_hours']:.2f} h of sim time), not the {REPORT_MIN_HOURS:g} h+ soak** "
                "(`--report`): memory growth over so short a span is not judged.", ""]
    verdict = "PASSED" if all(c["ok"] for c in doc["checks"]) else "FAILED"
    out += ["| | |", "|---|---|",
            f"| Date (UTC) | {m.get('date_utc') or 'unknown'} |",
            f"| Commit | {commit} |",
            f"| Machine | {m.get('cpu') or 'CPU unknown'}, {m.get('cores') or '?'} cores |",
            f"| Robots, seed | {doc['robots']} ({', '.join(doc['names'])}), seed {doc['seed']} |",
            f"| Sim time | {doc['sim_hours']:.2f} h asked; {fmt_duration(doc['sim_seconds'])} run + "
            f"{fmt_duration(doc['drain_seconds'])} drain |",
            f"| Wall time | {fmt_duration(doc['wall_seconds'])} |",
            f"| Real-time factor | {doc['rtf_achieved']:.2f} achieved ({doc['rtf_asked']} asked) |",
            f"| Batteries | {doc['battery']['battery_capacity_ah']} Ah from "
            f"{start_socs(doc['battery'])}, charger {doc['battery']['charge_current']:g} A "
            "(the world's `sim_params`) |",
            f"| Result | **{verdict}** |", "",
            "## Checks", "", "| check | ok | detail |", "|---|:-:|---|"]
    out += [f"| {c['check']} | {'yes' if c['ok'] else 'NO'} | {c['detail']} |" for c in doc["checks"]]
    out += ["", "## Orders", "",
            f"Placed {o['placed']} (a Poisson stream, one order every {doc['order_every_s']:g} s of sim time on "
            f"average, one or two tables each); served {o['served']}, failed {o['failed']}, cancelled "
            f"{o['cancelled']}; lost {len(o['lost'])}; served twice or changed after the end "
            f"{len(o['duplicated'])}; not accepted {len(doc['not_accepted'])}; placed late because the dispatcher was "
            f"restarting {doc.get('held_during_dispatcher_restart', 0)}.", "",
            f"Throughput {_f(s['orders_per_hour'])} orders/h; wait from order to the robot at its last table: "
            f"median {_f(s['wait_median_s'])} s, 95th percentile {_f(s['wait_p95_s'])} s.", ""]
    if o["reasons"]:
        out += ["| reason (failed / cancelled) | orders |", "|---|--:|"]
        out += [f"| {r.replace('|', '/')} | {n} |" for r, n in sorted(o["reasons"].items(), key=lambda kv: -kv[1])]
        out.append("")
    out += [f"Bumper contacts (presses): {', '.join(f'{k} {v}' for k, v in doc['contacts'].items())}.", "",
            "## Faults", "", "| at (sim s) | fault | detected | back in service | detail |", "|--:|---|--:|--:|---|"]
    for f in doc["faults"]:
        out.append(f"| {f['at']:.0f} | {f['kind']} {f['target']} | {_f(f.get('detected_s'))} s | "
                   f"{_f(f.get('recovery_s'))} s | {f.get('detail', '')} |")
    out += ["", "Robot: *detected* is sim s from the kill to the dispatcher showing it `offline`; *back in "
            "service* is sim s from its stack's restart to a state in service; the detail compares the robot's "
            f"own pose (on /fleet/robots) with the simulator's ground truth until it is within {LOCALIZED_M} m. "
            "Dispatcher: *detected* is "
            "sim s to the respawned node's pid; *back* sim s from the kill to its first queue.", "",
            f"Battery charges completed (charging, then back in service): {doc['charges_completed']} "
            f"({', '.join(f'{k} {v}' for k, v in doc['charges'].items())}); lowest charge seen "
            f"{', '.join(f'{k} {v:.0%}' for k, v in doc['battery_min'].items())}.", "",
            "## Memory", "",
            f"RSS of every node every {doc['sample_every_s']:g} s of wall time; growth is the least-squares slope over "
            f"the node's longest run (one pid) after {doc['warmup_s']:.0f} s of warm-up.", "",
            "| node | runs | RSS start (MB) | RSS end (MB) | growth (MB/h) | fit span |", "|---|--:|--:|--:|--:|--:|"]
    for r in doc["memory"]:
        out.append(f"| `{r['node']}` | {r['runs']} | {_f(r['rss_start_mb'])} | {_f(r['rss_end_mb'])} | "
                   f"{_f(r['growth_mb_h'], '+.2f')} | {fmt_duration(r['fit_span_s'])} |")
    out += ["", "## Restarts by something else", ""]
    out += [f"* `{r['node']}`: {r['what']}" for r in doc["restarts_by_others"]] or ["None."]
    return "\n".join(out) + "\n"


# ----------------------------------------------------------------- the run (ROS)
class _Timeout(xmlrpc.client.Transport):
    def __init__(self, timeout: float) -> None:
        super().__init__()
        self.timeout = timeout

    def make_connection(self, host):
        conn = super().make_connection(host)
        conn.timeout = self.timeout
        return conn


def rss_bytes(pid: int) -> float | None:
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return float(line.split()[1]) * 1024.0
    except OSError:
        return None
    return None


class Sampler(threading.Thread):
    """Every node's pid (master lookupNode + the node's getPid) and RSS, every ``every`` s of wall time."""

    def __init__(self, uri: str, every: float, ignore: str) -> None:
        super().__init__(daemon=True)
        self.uri, self.every, self.ignore = uri, every, ignore
        self.series: dict[str, list[tuple[float, int | None, float | None]]] = {}
        self.lock = threading.Lock()
        self.stop = threading.Event()
        self.t0 = time.monotonic()

    def pid_of(self, node: str) -> int | None:
        try:
            master = xmlrpc.client.ServerProxy(self.uri, transport=_Timeout(3.0))
            code, _, node_uri = master.lookupNode("/soak", node)
            if code != 1:
                return None
            code, _, pid = xmlrpc.client.ServerProxy(node_uri, transport=_Timeout(3.0)).getPid("/soak")
            return int(pid) if code == 1 else None
        except (OSError, xmlrpc.client.Error, ValueError):
            return None

    def nodes(self) -> set[str]:
        try:
            code, _, state = xmlrpc.client.ServerProxy(self.uri, transport=_Timeout(5.0)).getSystemState("/soak")
        except (OSError, xmlrpc.client.Error):
            return set()
        return {n for kind in state for _, names in kind for n in names} if code == 1 else set()

    def sample(self) -> None:
        t = time.monotonic() - self.t0
        with self.lock:
            names = set(self.series) | self.nodes()
        for node in sorted(names):
            if node.startswith(self.ignore):
                continue
            pid = self.pid_of(node)
            rss = rss_bytes(pid) if pid is not None else None
            with self.lock:
                self.series.setdefault(node, []).append((t, pid if rss is not None else None, rss))

    def pid(self, node: str) -> int | None:
        with self.lock:
            seq = self.series.get(node, [])
            return seq[-1][1] if seq else None

    def now(self) -> float:
        return time.monotonic() - self.t0

    def run(self) -> None:
        while not self.stop.is_set():
            self.sample()
            self.stop.wait(self.every)


class Fleet:
    """The run's processes: roscore, the world, the server, one roslaunch per robot (restartable)."""

    def __init__(self, args, files: dict, names: list[str], uri: str, port: int) -> None:
        self.args, self.files, self.names, self.uri, self.port = args, files, names, uri, port
        self.env = dict(os.environ, ROS_MASTER_URI=uri, ROS_HOME=str(LOG_DIR / "ros_home"))
        self.groups: list[ProcessGroup] = []
        self.robot_groups: dict[str, ProcessGroup] = {}
        self.starts = {n: 0 for n in names}

    def start(self, cmd: list[str], log: str) -> ProcessGroup:
        g = ProcessGroup(cmd, env=self.env, log=LOG_DIR / log).__enter__()
        self.groups.append(g)
        return g

    def start_robot(self, name: str) -> None:
        self.starts[name] += 1
        self.robot_groups[name] = self.start(
            ["roslaunch", "--wait", "chefbot_sim", "fleet_robot.launch", f"robot:={name}",
             f"fleet_file:={self.files['fleet']}"], f"robot_{name}_{self.starts[name]}.log")

    def kill_robot(self, name: str) -> None:
        """SIGKILL to the robot's roslaunch and every node it started (a power cut of its PC)."""
        g = self.robot_groups.pop(name)
        self.groups.remove(g)                  # first: its end is the test's, not a process that ended
        tracked = group_tree(g.proc.pid)
        for pid in tracked:
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        g.proc.wait(timeout=10)
        stop_tracked(tracked, 1.0)
        g.stop()

    def stop_all(self) -> None:
        for g in reversed(self.groups):        # robots and server first, roscore last
            g.stop()
        self.groups.clear()

    def dead(self) -> str | None:
        """The log of a part that ended on its own (the world is required: it ending ends the run)."""
        for g in list(self.groups):
            if g.poll() is not None:
                return str(g.log.relative_to(ROOT))
        return None


def wait(cond, timeout_s: float, what: str, fleet: Fleet) -> None:
    deadline = time.monotonic() + timeout_s
    while not cond():
        dead = fleet.dead()
        if dead:
            raise SoakError(f"{what}: a process ended; see {dead}")
        if time.monotonic() > deadline:
            raise SoakError(f"{what}: not within {timeout_s:.0f} s of wall time")
        time.sleep(0.2)


class Soak:
    """The order stream, the faults, the judge."""

    def __init__(self, args, fleet: Fleet, tables: dict, stream: list, sampler: Sampler) -> None:
        import rospy

        from chefbot_fleet.msg import OrderQueue
        from chefbot_msgs.msg import RobotState

        self.args, self.fleet, self.stream, self.sampler = args, fleet, stream, sampler
        self.names = fleet.names
        self.watch = Watch(self.names, tables)
        self.lock = threading.Lock()
        self.histories: dict[str, list[tuple[str, str, float]]] = {}
        self.robot_states: dict[str, list[tuple[str, str, float]]] = {n: [] for n in self.names}
        self.battery_min = {n: 1.0 for n in self.names}
        self.reported: dict[str, tuple[float, float, float]] = {}   # name -> x, y, sim t (its own RobotState)
        self.queue_stamps = 0
        self.kills: list[tuple[float, str]] = []      # (sampler wall s, node or namespace prefix)
        self.faults: list[dict] = []
        self.error: str | None = None
        self.dispatcher_down = threading.Event()      # set from its kill to its first queue: orders wait
        self.held = 0                                 # orders placed late for that
        rospy.Subscriber("/fleet/orders", OrderQueue, self._on_queue, queue_size=50)
        rospy.Subscriber("/fleet/robots", RobotState, self._on_robot, queue_size=50)

    def _on_queue(self, m) -> None:
        import rospy

        t = rospy.get_time()
        with self.lock:
            self.queue_stamps += 1
            record_states(self.histories, [(o.id, o.state, o.reason) for o in m.orders], t)
            for r in m.robots:
                if r.name in self.robot_states:
                    seq = self.robot_states[r.name]
                    if not seq or seq[-1][0] != r.state:
                        seq.append((r.state, r.reason, t))
                    if 0.0 <= r.battery <= 1.0:
                        self.battery_min[r.name] = min(self.battery_min[r.name], float(r.battery))

    def _on_robot(self, m) -> None:
        with self.lock:
            self.reported[m.name] = (m.pose.x, m.pose.y, m.header.stamp.to_sec())

    def robot_state(self, name: str) -> str:
        with self.lock:
            seq = self.robot_states[name]
            return seq[-1][0] if seq else ""

    # -- faults
    def sim_wait(self, until: float) -> None:
        import rospy

        deadline = time.monotonic() + max(STEP_TIMEOUT_S, (until - rospy.get_time()) / 0.05)
        while rospy.get_time() < until:
            if time.monotonic() > deadline:
                raise SoakError(f"sim time did not reach {until:.0f} s")
            time.sleep(0.2)

    def in_open_floor(self, name: str, keep_clear: list[tuple[float, float]]) -> bool:
        with self.lock:
            here = self.reported.get(name)
        return here is not None and min(math.hypot(here[0] - x, here[1] - y) for x, y in keep_clear) > OPEN_FLOOR_M

    def robot_fault(self, f: dict, keep_clear: list[tuple[float, float]]) -> None:
        import rospy

        name = f["target"]
        limit = rospy.get_time() + 120.0
        while not self.in_open_floor(name, keep_clear) and rospy.get_time() < limit:    # bounded: then anyway
            time.sleep(0.2)
        f["state_at_kill"] = self.robot_state(name)
        with self.lock:
            mine, truth = self.reported.get(name), self.watch.truth.get(name)
        f["pose_error_at_kill_m"] = math.hypot(mine[0] - truth[0], mine[1] - truth[1]) if mine and truth else None
        t_kill = rospy.get_time()
        self.kills.append((self.sampler.now(), f"/{name}/"))
        self.fleet.kill_robot(name)
        say(f"killed {name}'s stack (SIGKILL to its roslaunch and every node of it) at "
            f"{t_kill - self.t0:.0f} s, while {f['state_at_kill'] or '?'}")
        wait(lambda: self.robot_state(name) == "offline", STEP_TIMEOUT_S, f"{name} offline", self.fleet)
        f["detected_s"] = rospy.get_time() - t_kill
        self.sim_wait(t_kill + self.args.downtime)
        t_start = rospy.get_time()
        self.fleet.start_robot(name)
        say(f"started {name}'s stack again after {t_start - t_kill:.0f} s")
        wait(lambda: self.robot_state(name) in IN_SERVICE + ("to_charger", "charging"), STEP_TIMEOUT_S,
             f"{name} back in service", self.fleet)
        f["recovery_s"] = rospy.get_time() - t_start
        # judge only: the robot's own pose against ground truth, until it is within LOCALIZED_M
        errors: list[tuple[float, float]] = []
        limit = rospy.get_time() + LOCALIZE_WINDOW_S
        wall_limit = time.monotonic() + STEP_TIMEOUT_S
        while rospy.get_time() < limit and time.monotonic() < wall_limit:
            with self.lock:
                mine, truth = self.reported.get(name), self.watch.truth.get(name)
            if mine and truth and mine[2] >= t_start:
                errors.append((rospy.get_time() - t_start, math.hypot(mine[0] - truth[0], mine[1] - truth[1])))
                if errors[-1][1] < LOCALIZED_M:
                    break
            time.sleep(0.5)
        f["pose_error_first_m"] = errors[0][1] if errors else None
        f["pose_error_max_m"] = max((e for _, e in errors), default=None)
        f["localized_s"] = errors[-1][0] if errors and errors[-1][1] < LOCALIZED_M else None
        f["detail"] = (f"killed while {f['state_at_kill'] or '?'} (own pose {_f(f['pose_error_at_kill_m'], '.2f')} m "
                       f"from the truth); down {t_start - t_kill:.0f} s; after the restart own pose "
                       f"{_f(f['pose_error_first_m'], '.2f')} m from the truth at first (at most "
                       f"{_f(f['pose_error_max_m'], '.2f')} m), within {LOCALIZED_M} m "
                       + (f"{f['localized_s']:.0f} s after its restart" if f["localized_s"] is not None
                          else f"NOT within {LOCALIZE_WINDOW_S:.0f} s"))
        f["recovered"] = f["localized_s"] is not None
        say(f"{name} back in service {f['recovery_s']:.1f} s after its restart ({f['detail']})")

    def dispatcher_fault(self, f: dict) -> None:
        import rospy

        old = self.sampler.pid_of("/fleet/dispatcher")
        t_kill = rospy.get_time()
        self.kills.append((self.sampler.now(), "/fleet/dispatcher"))
        self.dispatcher_down.set()
        out = subprocess.run(["rosnode", "kill", "/fleet/dispatcher"], capture_output=True, text=True,
                             timeout=30, env=self.fleet.env)
        say(f"rosnode kill /fleet/dispatcher at {t_kill - self.t0:.0f} s: {out.stdout.strip() or out.stderr.strip()}")
        wait(lambda: self.sampler.pid_of("/fleet/dispatcher") not in (None, old), STEP_TIMEOUT_S,
             "the dispatcher respawned", self.fleet)
        f["detected_s"] = rospy.get_time() - t_kill
        with self.lock:
            stamps = self.queue_stamps
        wait(lambda: self.queue_stamps > stamps, STEP_TIMEOUT_S, "the respawned dispatcher's queue", self.fleet)
        f["recovery_s"] = rospy.get_time() - t_kill
        time.sleep(1.0)                           # the action client meets the new server
        self.dispatcher_down.clear()
        f["recovered"] = True
        f["detail"] = f"pid {old} -> {self.sampler.pid_of('/fleet/dispatcher')} (roslaunch respawn)"
        say(f"the dispatcher is back: {f['detail']}, its queue {f['recovery_s']:.1f} s after the kill")

    def run_faults(self, schedule: list[dict]) -> None:
        from chefbot_common.fleet_file import load_kitchen

        k = load_kitchen(self.fleet.files["fleet"])
        keep_clear = [(k.x, k.y), *[(t.x, t.y) for t in self.watch.tables.values()]]
        try:
            for f in schedule:
                self.sim_wait(self.t0 + f["at"])
                f = dict(f, at=f["at"])
                self.faults.append(f)
                if f["kind"] == "robot":
                    self.robot_fault(f, keep_clear)
                else:
                    self.dispatcher_fault(f)
        except Exception as exc:  # noqa: BLE001 - reported by the main loop, which stops the run
            self.error = f"fault injection: {exc}"

    # -- orders
    def run(self, schedule: list[dict]) -> dict:
        import actionlib
        import rospy
        from actionlib_msgs.msg import GoalStatus

        from chefbot_fleet.msg import DeliverAction, DeliverGoal

        client = actionlib.ActionClient("/fleet/deliver", DeliverAction)
        wait(lambda: client.wait_for_server(rospy.Duration(0.1)) and
             all(self.robot_state(n) == "idle" for n in self.names), STARTUP_TIMEOUT_S,
             "the dispatcher and every robot idle", self.fleet)
        self.t0 = rospy.get_time()
        wall0 = time.monotonic()
        end = self.t0 + self.args.hours * 3600.0
        say(f"every robot idle; {len(self.stream)} orders over {self.args.hours * 3600:.0f} s of sim time; faults: " +
            ", ".join(f"{f['kind']} {f['target']} at {f['at']:.0f} s" for f in schedule))
        faults = threading.Thread(target=self.run_faults, args=(schedule,), daemon=True)
        faults.start()
        todo = list(self.stream)
        pending: list[dict] = []              # goals waiting for their id
        placed: dict[str, float] = {}
        not_accepted: list[list[str]] = []
        goals = []                            # keep every goal handle alive (a dropped one is cancelled)
        wall_limit = wall0 + self.args.max_wall_hours * 3600.0
        last_note = time.monotonic()
        while True:
            now = rospy.get_time()
            if self.error:
                raise SoakError(self.error)
            dead = self.fleet.dead()
            if dead:
                raise SoakError(f"a process ended; see {dead}")
            if time.monotonic() > wall_limit:
                raise SoakError(f"the run took more than --max-wall-hours {self.args.max_wall_hours:g}")
            while todo and now >= self.t0 + todo[0][0] and not self.dispatcher_down.is_set():
                due, tables = todo.pop(0)
                self.held += now - (self.t0 + due) > 5.0
                gh = client.send_goal(DeliverGoal(tables=tables, priority=1.0))
                goals.append(gh)
                pending.append({"gh": gh, "tables": tables, "placed": now, "wall": time.monotonic()})
            for p in list(pending):
                if p["gh"].get_goal_status() == GoalStatus.ACTIVE or p["gh"].get_goal_status() in (
                        GoalStatus.SUCCEEDED, GoalStatus.ABORTED):
                    text = p["gh"].get_goal_status_text().split()
                    result = p["gh"].get_result()
                    oid = (result.order_id if result is not None and result.order_id else "") or \
                        (text[-1] if text and text[-1].startswith("o") else "")
                    if oid:
                        placed[oid] = p["placed"]
                        pending.remove(p)
                        continue
                if time.monotonic() - p["wall"] > ACCEPT_TIMEOUT_S:
                    say(f"NOT ACCEPTED: an order for {', '.join(p['tables'])} "
                        f"({p['gh'].get_goal_status_text() or 'no answer'})")
                    not_accepted.append(p["tables"])
                    pending.remove(p)
            if time.monotonic() - last_note > 60.0:
                last_note = time.monotonic()
                with self.lock:
                    done = sum(1 for i in placed if any(s in FINAL for s, _, _ in self.histories.get(i, [])))
                say(f"{(now - self.t0) / 60:5.1f} min of {self.args.hours * 60:.0f} (RTF "
                    f"{(now - self.t0) / max(1e-6, time.monotonic() - wall0):.2f}): {len(placed)} placed, "
                    f"{done} ended; "
                    "robots " + ", ".join(f"{n} {self.robot_state(n)}" for n in self.names))
            if now >= end and not todo and not pending and not faults.is_alive():
                break
            time.sleep(0.1)
        sim_s = rospy.get_time() - self.t0
        say(f"stream over ({len(placed)} orders placed); draining for up to {self.args.drain:.0f} s of sim time")
        drain_end = rospy.get_time() + self.args.drain
        drain_wall = time.monotonic() + self.args.drain / 0.05

        def open_orders() -> list[str]:
            with self.lock:
                return [i for i in placed if not any(s in FINAL for s, _, _ in self.histories.get(i, []))]
        while open_orders() and rospy.get_time() < drain_end and time.monotonic() < drain_wall \
                and not self.fleet.dead():
            time.sleep(0.5)
        time.sleep(2.0)                          # the last queue messages
        drain_s = rospy.get_time() - self.t0 - sim_s
        wall_s = time.monotonic() - wall0
        return {"placed": placed, "not_accepted": not_accepted, "held": self.held,
                "sim_s": sim_s, "drain_s": drain_s, "wall_s": wall_s}


def charges_completed(states: list[tuple[str, str, float]]) -> int:
    """How often a robot went from ``charging`` back into service (the soak sends no robot to charge:
    each is its battery's rule)."""
    return sum(1 for (a, _, _), (b, _, _) in zip(states, states[1:], strict=False)
               if a == "charging" and b in IN_SERVICE)


def write_outputs(doc: dict, report: bool) -> None:
    OUT.mkdir(exist_ok=True)
    stamp = doc["time_utc"]
    for name in (f"soak-{stamp}.json", "soak-latest.json"):
        (OUT / name).write_text(json.dumps(doc, indent=2) + "\n")
    say(f"JSON: {(OUT / f'soak-{stamp}.json').relative_to(ROOT)} (and soak-latest.json)")
    if report or doc["sim_hours"] >= REPORT_MIN_HOURS:
        REPORT.write_text(render_report(doc))
        say(f"report: {REPORT.relative_to(ROOT)}")
    else:
        say(f"{REPORT.relative_to(ROOT)} left as it is (a run under {REPORT_MIN_HOURS:g} h; --report writes it)")


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--hours", type=float, default=2.0, help="sim hours of orders (fractional: 0.15)")
    ap.add_argument("--robots", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--order-every", type=float, default=30.0, help="mean sim s between orders")
    ap.add_argument("--downtime", type=float, default=30.0, help="sim s a killed robot's stack stays down")
    ap.add_argument("--drain", type=float, default=900.0, help="sim s after the stream for the last orders")
    ap.add_argument("--sample-every", type=float, default=10.0, help="wall s between memory samples")
    ap.add_argument("--rtf", default="1.0", help="the world's real_time_factor")
    ap.add_argument("--max-wall-hours", type=float, default=None,
                    help="give up after this many wall hours (default 4 x --hours + 0.5)")
    ap.add_argument("--report", action="store_true", help=f"write {REPORT.relative_to(ROOT)} even for a short run")
    ap.add_argument("--render", type=Path, help="only rebuild the report from this soak JSON")
    args = ap.parse_args()
    if args.render:
        REPORT.write_text(render_report(json.loads(args.render.read_text())))
        say(f"report: {REPORT.relative_to(ROOT)}")
        return 0
    if not args.hours > 0 or args.order_every <= 0 or args.downtime < 0 or args.sample_every <= 0:
        say("ERROR: --hours, --order-every and --sample-every must be > 0, --downtime >= 0")
        return 2
    if args.max_wall_hours is None:
        args.max_wall_hours = 4.0 * args.hours + 0.5
    try:
        files = {k: str(Path(v).resolve()) for k, v in site_files().items()}
        robots, tables, table_names = load_site(files, args.robots)
    except FleetDemoError as exc:
        say(f"ERROR: {exc}")
        return 2
    names = [r.name for r in robots]
    sim_s = args.hours * 3600.0
    count = max(1, int(sim_s / args.order_every))
    stream = [o for o in order_stream(table_names, count * 2, args.order_every, args.seed) if o[0] < sim_s][:count * 2]
    schedule = fault_schedule(sim_s, names, args.seed)
    battery = sim_battery(args.hours, names)
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    sim_params = LOG_DIR / "sim_params.yaml"
    sim_params.write_text(yaml.safe_dump(battery, sort_keys=False))
    database = LOG_DIR / "orders.sqlite"
    database.unlink(missing_ok=True)
    meta = collect_meta()
    port = free_port()
    uri = f"http://127.0.0.1:{port}"
    os.environ.update(ROS_MASTER_URI=uri, ROS_HOME=str(LOG_DIR / "ros_home"))
    fleet = Fleet(args, files, names, uri, port)
    sampler = Sampler(uri, args.sample_every, "/chefbot_fleet_soak")
    say(f"{len(names)} robots ({', '.join(names)}), {args.hours:g} h of sim time, seed {args.seed}; master {uri}; "
        f"logs in {LOG_DIR.relative_to(ROOT)}; batteries {battery}")
    try:
        fleet.start(["roscore", "-p", str(port)], "roscore.log")
        fleet.start(["roslaunch", "--wait", "chefbot_sim", "fleet_sim.launch", f"robots:={len(names)}",
                     f"world:={files['world']}", f"fleet_file:={files['fleet']}", f"real_time_factor:={args.rtf}",
                     "use_imu:=true", f"seed:={args.seed}", f"sim_params:={sim_params}"], "world.log")
        import rosgraph

        master = rosgraph.Master("/chefbot_fleet_soak")
        wait(lambda: master.is_online() and master.hasParam("/use_sim_time") and master.getParam("/use_sim_time"),
             STARTUP_TIMEOUT_S, "the world", fleet)
        fleet.start(["roslaunch", "--wait", "chefbot_fleet", "fleet_server.launch", f"robots:={' '.join(names)}",
                     f"map_file:={files['map']}", f"fleet_file:={files['fleet']}", f"tables_file:={files['tables']}",
                     f"database:={database}", "respawn:=true", "sim_time:=true"], "server.log")
        for n in names:
            fleet.start_robot(n)
        import rospy

        rospy.init_node("chefbot_fleet_soak", anonymous=True, disable_signals=True)
        soak = Soak(args, fleet, tables, stream, sampler)
        sampler.start()
        run = soak.run(schedule)
        sampler.stop.set()
        sampler.join(timeout=60)
        sampler.sample()                         # the end's pids
    except (SoakError, TimeoutError, FleetDemoError, subprocess.SubprocessError) as exc:
        say(f"ERROR: {exc}")
        return 1
    except KeyboardInterrupt:
        say("interrupted")
        return 130
    finally:
        sampler.stop.set()
        say("stopping every process of the run")
        fleet.stop_all()
    return judge(args, meta, names, battery, soak, sampler, run)


def judge(args, meta: dict, names: list[str], battery: dict, soak: Soak, sampler: Sampler, run: dict) -> int:
    with soak.lock:
        histories = {k: list(v) for k, v in soak.histories.items()}
    orders = judge_orders(run["placed"], histories)
    results = []
    served_away = []
    queue = {k: v for k, v in soak.watch.orders().items()}
    for oid, t in run["placed"].items():
        seq = histories.get(oid, [])
        final = next(((s, tt) for s, _, tt in seq if s in FINAL), None)
        ok = final is not None and final[0] == "served"
        results.append({"placed": t, "ended": final[1] if final else None, "ok": ok})
        dist = soak.watch.served_at.get(oid)
        if ok and (dist is None or dist > SERVED_AWAY_M):
            robot = getattr(queue.get(oid), "assigned", "?")
            served_away.append(f"{oid} ({robot}, {_f(dist, '.2f')} m)")
    charges = {n: charges_completed(soak.robot_states[n]) for n in names}
    warmup = min(300.0, 0.2 * run["wall_s"])
    doc = {"time_utc": dt.datetime.now(dt.UTC).strftime("%Y%m%dT%H%M%SZ"), "meta": meta,
           "robots": len(names), "names": names, "seed": args.seed, "sim_hours": args.hours,
           "sim_seconds": run["sim_s"], "drain_seconds": run["drain_s"], "wall_seconds": run["wall_s"],
           "rtf_asked": args.rtf, "rtf_achieved": (run["sim_s"] + run["drain_s"]) / max(1e-6, run["wall_s"]),
           "order_every_s": args.order_every, "battery": battery, "orders": orders,
           "summary": summarise(results, len(names)), "not_accepted": run["not_accepted"],
           "held_during_dispatcher_restart": run["held"],
           "served_away": served_away, "served_within_xy_tol": sum(
               1 for d in soak.watch.served_at.values() if d <= XY_TOL),
           "contacts": soak.watch.contacts, "bumper_pressed_samples": soak.watch.bumps,
           "faults": soak.faults, "charges": charges, "charges_completed": sum(charges.values()),
           "battery_min": soak.battery_min, "sample_every_s": args.sample_every, "warmup_s": warmup,
           "memory": memory_table(sampler.series, warmup),
           "restarts_by_others": restarts_by_others(sampler.series, soak.kills),
           "robot_states": soak.robot_states}
    doc["checks"] = checks(doc)
    write_outputs(doc, args.report)
    s = doc["summary"]
    say(f"sim {fmt_duration(run['sim_s'])} + drain {fmt_duration(run['drain_s'])} in {fmt_duration(run['wall_s'])} "
        f"wall (RTF {doc['rtf_achieved']:.2f}); orders placed {orders['placed']}: served {orders['served']}, failed "
        f"{orders['failed']}, cancelled {orders['cancelled']}, lost {len(orders['lost'])}, duplicated "
        f"{len(orders['duplicated'])}; {_f(s['orders_per_hour'])} orders/h; contacts {doc['contacts']}")
    for r in doc["memory"]:
        say(f"memory {r['node']}: {_f(r['rss_start_mb'])} -> {_f(r['rss_end_mb'])} MB, "
            f"{_f(r['growth_mb_h'], '+.2f')} MB/h over {fmt_duration(r['fit_span_s'])}")
    for c in doc["checks"]:
        say(f"{'ok  ' if c['ok'] else 'FAIL'} {c['check']}: {c['detail']}")
    return 0 if all(c["ok"] for c in doc["checks"]) else 1


if __name__ == "__main__":
    signal.signal(signal.SIGINT, signal.default_int_handler)   # Ctrl-C even when started in the background
    stop_on_sigterm()
    sys.exit(main())
