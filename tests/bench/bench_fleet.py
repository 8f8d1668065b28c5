"""Several robots in one site: the multi-robot issue's scenarios, seeded, against each robot alone.

tools/fleet_scenarios.py runs each scenario (two robots head-on: in the café's single-lane aisle s1, at
a 1.0 m chair pinch in the hotel; two crossing at a junction; three swapping places across the room; a
robot parked on another's goal, which the fleet must move) with the full stack per robot -- pybullet,
amcl, move_base with the robots layer, the traffic node -- at real time (``real_time_factor`` 1.0),
``CHEFBOT_FLEET_SEEDS`` times (default 20, as the multi-robot issue asks; quick: 1; about 50 s of wall
time per run, so some 2.5 h for the eight scenarios). Each robot's leg is also run once with the robot
alone in the site. Per scenario: arrivals (goal all), bumper contacts (goal 0; the simulator's ground
truth, a test oracle), robots that did not arrive within the leg timeout or aborted (a deadlock shows
here), the time each robot lost to the others (its time minus its time alone; median and worst over
robots and seeds), and what the stacks cost while the robots drive: the slowest run's sim seconds per
wall second (three full stacks on two cores may run below real time; every result is judged in sim
time) and the CPU seconds per sim second of each robot's stack and of the simulator, for one robot (each
leg alone), two and three. Each site is its own section of the report
(``fleet hotel``, ``fleet cafe``), so ``CHEFBOT_FLEET_SITES`` (comma-separated, default all; e.g.
``cafe``) reruns one site and keeps the other's figures.
"""
from __future__ import annotations

import os
import statistics
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))


def _speed_rows(bench: str, case: str, drives) -> list[dict]:
    """Sim s per wall s (the slowest run) and CPU s per sim s of each robot stack and of the simulator
    (means over the runs) while the robots drove: what 1, 2 or 3 full stacks cost on this machine."""
    rtf = min(d.seconds / max(d.wall_seconds, 1e-9) for d in drives)
    stack = statistics.mean(d.cpu[n] / max(d.seconds, 1e-9) for d in drives for n in (r.name for r in d.robots))
    sim = statistics.mean(d.cpu["sim"] / max(d.seconds, 1e-9) for d in drives)
    rest = statistics.mean(d.cpu["rest"] / max(d.seconds, 1e-9) for d in drives)
    return [
        {"bench": bench, "case": case, "metric": "sim s per wall s (slowest run)", "ours": rtf, "reference": 1.0,
         "reference_name": "asked", "goal": None, "met": None},
        {"bench": bench, "case": case, "metric": "CPU s per sim s, each robot's stack", "ours": stack,
         "reference": None, "reference_name": None, "goal": None, "met": None},
        {"bench": bench, "case": case, "metric": "CPU s per sim s, the simulator", "ours": sim,
         "reference": rest, "reference_name": "master, map_server, traffic, roslaunch", "goal": None,
         "met": None},
    ]


def run(quick: bool = False) -> list[dict]:
    import fleet_scenarios as fs

    seeds = 1 if quick else int(os.environ.get("CHEFBOT_FLEET_SEEDS", "20"))
    sites = [s for s in os.environ.get("CHEFBOT_FLEET_SITES", "").split(",") if s] or list(fs.SCENARIOS)
    unknown = [s for s in sites if s not in fs.SCENARIOS]
    if unknown:
        raise ValueError(f"CHEFBOT_FLEET_SITES: unknown site(s) {unknown}; known: {sorted(fs.SCENARIOS)}")
    rows = []
    for site in sites:
        bench = f"fleet {site}"
        solo_drives = []
        for name, legs in fs.SCENARIOS[site].items():
            case = f"{name} ({len(legs)} robots, {seeds} seed{'s' if seeds > 1 else ''})"
            alone = []
            for i, (_, goal) in enumerate(legs):
                if goal is None:        # a parked robot: nothing to time alone
                    alone.append(None)
                    continue
                solo = fs.run_process(site, name, seed=0, only=i)
                solo_drives.append(solo)
                alone.append(solo.robots[0].seconds if solo.robots[0].arrived else None)
            arrived = total = contacts = 0
            lost, failures, drives = [], [], []
            for seed in range(seeds):
                drive = fs.run_process(site, name, seed=seed)
                drives.append(drive)
                for r, solo in zip(drive.robots, alone, strict=True):
                    contacts += r.bumps
                    if r.parked:            # no goal: only its contacts count
                        continue
                    total += 1
                    if r.arrived:
                        arrived += 1
                        if solo is not None:
                            lost.append(r.seconds - solo)
                    else:
                        failures.append(f"{r.name} seed {seed}: {r.state} {r.text}")
                print(f"[bench] {bench} {case} seed {seed}: " + "; ".join(
                    f"{r.name} {r.state} {r.seconds:.1f} s, {r.bumps} bumps" for r in drive.robots), flush=True)
            for f in failures:
                print(f"[bench] {bench} {case}: not arrived: {f}", flush=True)
            rows += [
                {"bench": bench, "case": case, "metric": "robots arrived", "ours": arrived, "reference": total,
                 "reference_name": "robots sent", "goal": f"{total}/{total}", "met": arrived == total},
                {"bench": bench, "case": case, "metric": "bumper contacts", "ours": contacts, "reference": None,
                 "reference_name": None, "goal": "0", "met": contacts == 0},
                {"bench": bench, "case": case, "metric": "s lost to the others, median", "ours":
                 statistics.median(lost) if lost else None, "reference": statistics.median(
                     [a for a in alone if a is not None]) if any(a is not None for a in alone) else None,
                 "reference_name": "s alone (median leg)", "goal": None, "met": None},
                {"bench": bench, "case": case, "metric": "s lost to the others, worst", "ours":
                 max(lost) if lost else None, "reference": None, "reference_name": None, "goal": None, "met": None},
            ]
            rows += _speed_rows(bench, case, drives)
        if solo_drives:
            rows += _speed_rows(bench, f"each leg alone (1 robot, {len(solo_drives)} legs)", solo_drives)
    return rows
