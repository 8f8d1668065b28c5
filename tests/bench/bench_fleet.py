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
robots and seeds) and the run's sim seconds per wall second (three full stacks on two cores may run
below real time; every result is judged in sim time). Each site is its own section of the report
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


def run(quick: bool = False) -> list[dict]:
    import fleet_scenarios as fs

    seeds = 1 if quick else int(os.environ.get("CHEFBOT_FLEET_SEEDS", "20"))
    sites = [s for s in os.environ.get("CHEFBOT_FLEET_SITES", "").split(",") if s] or list(fs.SCENARIOS)
    unknown = [s for s in sites if s not in fs.SCENARIOS]
    if unknown:
        raise ValueError(f"CHEFBOT_FLEET_SITES: unknown site(s) {unknown}; known: {sorted(fs.SCENARIOS)}")
    rows = []
    for site in sites:
        scenarios = fs.SCENARIOS[site]
        for name, legs in scenarios.items():
            bench = f"fleet {site}"
            case = f"{name} ({len(legs)} robots, {seeds} seed{'s' if seeds > 1 else ''})"
            alone = []
            for i, (_, goal) in enumerate(legs):
                if goal is None:        # a parked robot: nothing to time alone
                    alone.append(None)
                    continue
                robots, _, _ = fs.run_process(site, name, seed=0, only=i)
                alone.append(robots[0].seconds if robots[0].arrived else None)
            arrived = total = contacts = 0
            lost, failures, rtfs = [], [], []
            for seed in range(seeds):
                robots, sim_s, wall_s = fs.run_process(site, name, seed=seed)
                rtfs.append(sim_s / max(wall_s, 1e-9))
                for r, solo in zip(robots, alone, strict=True):
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
                    f"{r.name} {r.state} {r.seconds:.1f} s, {r.bumps} bumps" for r in robots), flush=True)
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
                {"bench": bench, "case": case, "metric": "sim s per wall s", "ours": min(rtfs),
                 "reference": 1.0, "reference_name": "asked", "goal": None, "met": None},
            ]
    return rows
