#!/usr/bin/env python3
"""Fleet scenarios: several robots in one simulated site, each sent from a start pose to a goal at once.

Each run launches ``fleet_world.launch`` with a fleet file written for the run (the robots' start poses),
sends every robot its goal at the same sim time through its own move_base (tools/delivery.py, which also
counts bumper contacts from the simulator's ground truth, a test oracle), and records per robot: the
result, the sim seconds to arrive, the final error, the bumper contacts.  ``alone`` runs one robot of a
scenario by itself in the same site, for the time each robot would take without the others.

The scenarios (``SCENARIOS``) are the multi-robot issue's: two robots head-on (in a single-lane aisle:
the café; at a 1.0 m chair pinch: the hotel), two crossing at a junction, three swapping places across
the room, and a robot parked on another's goal (in the hotel's open room; in the café, at a table in a
dead-end aisle).  A parked robot gets no goal (its goal is None): the fleet must move it out of the way;
its result is ``PARKED`` with the distance it moved (``xy_error``) and its bumper contacts.  Every start
and goal is checked to be free on the site's map (0.25 m from any obstacle).

Used by tests/bench/bench_fleet.py (one process per run: rospy joins one master per process); by hand
(JSON out; ``--only=I``: robot I's leg alone):
    python tools/fleet_scenarios.py hotel head_on [SEED] [--only=I] [--keep-logs]
"""
from __future__ import annotations

import json
import math
import os
import shutil
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from procs import free_port, run_captured, stop_on_sigterm, tree_cpu

ROOT = Path(__file__).resolve().parent.parent
MAPS = ROOT / "chefbot_navigation" / "maps"
WORLDS = ROOT / "chefbot_sim" / "worlds"
SITES = {   # world, map (the world's frame)
    "hotel": (WORLDS / "hotel.yaml", MAPS / "hotel_world_map.yaml"),
    "cafe": (WORLDS / "cafe.yaml", MAPS / "cafe_map.yaml"),
}
H = math.pi
Pose = tuple[float, float, float]
#: site -> scenario -> [(start (x, y, yaw), goal (x, y, yaw) or None: parked)], robots chefbot1, chefbot2, ... in order
SCENARIOS: dict[str, dict[str, list[tuple[Pose, Pose | None]]]] = {
    "hotel": {
        "head_on": [((1.4, -1.5, 0.0), (4.6, -1.5, 0.0)), ((4.3, -1.5, H), (1.1, -1.5, H))],      # 1.0 m pinch
        "crossing": [((1.4, -1.5, 0.0), (7.4, -1.5, 0.0)), ((4.4, -4.4, H / 2), (4.4, 1.5, H / 2))],
        "swap3": [((0.0, -1.5, 0.0), (10.5, -1.5, 0.0)), ((10.5, -1.5, H), (0.0, 1.5, H)),
                  ((0.0, 1.5, -H / 2), (0.0, -1.5, -H / 2))],
        "parked": [((0.0, 1.5, 0.0), (4.4, 1.5, 0.0)), ((4.4, 1.5, H / 2), None)],
    },
    "cafe": {
        "head_on": [((2.025, 0.4, H / 2), (1.0, 2.3, H)), ((3.2, 2.3, H), (2.025, 0.4, -H / 2))],   # aisle s1
        "crossing": [((3.775, 4.2, -H / 2), (3.425, 0.4, -H / 2)), ((1.0, 2.3, 0.0), (6.5, 2.3, 0.0))],
        "swap3": [((0.5, 2.3, 0.0), (6.5, 2.3, 0.0)), ((6.5, 2.3, H), (2.15, 4.2, H / 2)),
                  ((2.15, 4.2, -H / 2), (0.5, 2.3, H))],
        "parked": [((1.0, 2.3, 0.0), (3.425, 0.4, -H / 2)), ((3.425, 0.4, -H / 2), None)],      # table_s2
    },
}
CLEARANCE = 0.25        # m from any obstacle a start or goal must have
LEG_TIMEOUT_S = 240.0   # wall s per robot's goal


class ScenarioError(ValueError):
    """A scenario that cannot run (unknown site or name, a pose in or too near an obstacle)."""


@dataclass
class RobotResult:
    """One robot's leg of a run."""

    name: str
    state: str
    text: str
    seconds: float          # sim s from the goal to the result
    xy_error: float         # m, ground truth vs goal
    bumps: int

    @property
    def arrived(self) -> bool:
        """Reached its goal."""
        return self.state == "SUCCEEDED"

    @property
    def parked(self) -> bool:
        """Had no goal (a parked robot; ``xy_error``: how far it moved)."""
        return self.state == "PARKED"


@dataclass
class Drive:
    """A run from the goals to the last result: every robot's leg, the sim and wall seconds it took, and
    the CPU seconds spent meanwhile by each robot's stack, the simulator and the rest (:func:`cpu_by_part`)."""

    robots: list[RobotResult]
    seconds: float
    wall_seconds: float
    cpu: dict[str, float]


def check_poses(site: str, legs) -> None:
    """ScenarioError naming every start or goal that is not CLEARANCE m clear of the map's obstacles."""
    import numpy as np
    from scipy import ndimage

    from chefbot_common.map_io import load_map

    occ = load_map(str(SITES[site][1]))
    free = (occ.data >= 0) & (occ.data < 50)
    dist = ndimage.distance_transform_edt(free) * occ.info.resolution
    bad = []
    for i, (start, goal) in enumerate(legs):
        for what, pose in (("start", start), ("goal", goal)):
            if pose is None:
                continue
            x, y, _ = pose
            r, c = (int(v) for v in occ.info.world_to_cell(x, y))
            ok = occ.info.inside(np.array(r), np.array(c)) and dist[r, c] >= CLEARANCE
            if not ok:
                bad.append(f"chefbot{i + 1} {what} ({x}, {y})")
    if bad:
        raise ScenarioError(f"{site}: not {CLEARANCE} m clear on {SITES[site][1].name}: {', '.join(bad)}")


def scenario(site: str, name: str):
    """The legs of a scenario (ScenarioError for an unknown one)."""
    try:
        return SCENARIOS[site][name]
    except KeyError:
        raise ScenarioError(f"no scenario {site}/{name}; there are: "
                            + ", ".join(f"{s}/{n}" for s in SCENARIOS for n in SCENARIOS[s])) from None


def run(site: str, legs, seed: int = 0, traffic: bool = True, rtf: float = 1.0, log_dir: Path | None = None,
        keep_logs: bool = False) -> Drive:
    """Run ``legs`` [(start, goal)] at once in ``site``; the robots' results, the sim and wall seconds
    until the last result and the CPU spent meanwhile.  The launch and its nodes are stopped before it
    returns.  The run's logs are kept (their directory named on stderr) when a robot failed or touched
    something, or with ``keep_logs``."""
    check_poses(site, legs)
    world, map_file = SITES[site]
    names = [f"chefbot{i + 1}" for i in range(len(legs))]
    tmp = Path(tempfile.mkdtemp(prefix="chefbot_fleet_scn_"))
    fleet = tmp / "fleet.yaml"
    lines = ["frame: map", f"site: {site}", "robots:"]
    for n, (start, _goal) in zip(names, legs, strict=True):
        lines += [f"  - name: {n}", f"    parking: {{x: {start[0]}, y: {start[1]}, yaw: {start[2]}}}"]
    fleet.write_text("\n".join(lines) + "\n")
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOME=str(log_dir or tmp / "ros_home"))
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_HOME=env["ROS_HOME"])
    with open(tmp / "roslaunch.log", "w") as log:
        launch = subprocess.Popen(
            ["roslaunch", "-p", str(port), "chefbot_sim", "fleet_world.launch", f"robots:={len(legs)}",
             f"fleet_file:={fleet}", f"world:={world}", f"map_file:={map_file}", f"seed:={seed}",
             f"traffic:={'true' if traffic else 'false'}", f"real_time_factor:={rtf}"],
            env=env, stdout=log, stderr=subprocess.STDOUT, start_new_session=True)
    keep = True     # the run's logs stay (printed) unless every robot arrived (or stayed parked) without contact
    try:
        drive = _drive(names, legs, launch, tmp)
        keep = keep_logs or not all((r.arrived or r.parked) and r.bumps == 0 for r in drive.robots)
        return drive
    finally:
        try:
            os.killpg(launch.pid, 2)
            launch.wait(60)
        except (ProcessLookupError, subprocess.TimeoutExpired):
            os.killpg(launch.pid, 9)
        if keep:
            print(f"fleet_scenarios: logs of this run: {tmp}", file=sys.stderr)
        else:
            shutil.rmtree(tmp, ignore_errors=True)


def _drive(names, legs, launch, tmp: Path) -> Drive:
    import rosgraph
    import rospy
    from delivery import DeliveryClient

    master = rosgraph.Master("/fleet_scenarios")
    deadline = time.monotonic() + 60.0
    while True:
        try:
            master.getPid()
            break
        except Exception:   # noqa: BLE001 -- the master is not up yet
            if time.monotonic() > deadline or launch.poll() is not None:
                raise RuntimeError(f"the launch did not come up; see {tmp / 'roslaunch.log'}") from None
            time.sleep(0.1)
    if not rospy.core.is_initialized():
        rospy.init_node("fleet_scenarios", anonymous=True, disable_signals=True)
    clients = [DeliveryClient(ns=n) for n in names]      # one after the other (tf2_frames service)
    for c in clients:
        c.wait_ready(180.0)
    for c in clients:
        c.wait_localized(120.0)
    results: dict[str, RobotResult] = {}

    def go(i: int) -> None:
        x, y, yaw = legs[i][1]
        leg = clients[i].deliver(names[i], x, y, yaw, LEG_TIMEOUT_S)
        results[names[i]] = RobotResult(names[i], leg.state, leg.text, leg.seconds, leg.xy_error, leg.bumps)

    def pose_now(c) -> tuple[float, float]:
        with c._lock:
            p = c._truth_pose()
        return p.x, p.y

    parked = {i: (pose_now(clients[i]), clients[i].bumps) for i, (_, goal) in enumerate(legs) if goal is None}
    cpu0, w0, t0 = tree_cpu(launch.pid), time.monotonic(), rospy.get_time()
    threads = [threading.Thread(target=go, args=(i,), daemon=True) for i in range(len(names)) if i not in parked]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    seconds, wall = rospy.get_time() - t0, time.monotonic() - w0
    cpu = cpu_by_part(cpu0, tree_cpu(launch.pid), names)
    for i, ((x0, y0), bumps0) in parked.items():
        x, y = pose_now(clients[i])
        moved = math.hypot(x - x0, y - y0)
        results[names[i]] = RobotResult(names[i], "PARKED", f"no goal; moved {moved:.2f} m", 0.0, moved,
                                        clients[i].bumps - bumps0)
    return Drive([results[n] for n in names], seconds, wall, cpu)


def cpu_by_part(before: dict[int, tuple[str, float]], after: dict[int, tuple[str, float]],
                names: list[str]) -> dict[str, float]:
    """CPU seconds spent between two :func:`procs.tree_cpu` readings, by part: each robot's stack (its
    nodes, namespaced ``NAME-``), ``sim`` (the simulator) and ``rest`` (master, rosout, map_server,
    traffic, roslaunch).  A process that started in between counts from 0; one that ended is missing
    from ``after`` and counts nothing (none should, while the robots drive)."""
    parts = dict.fromkeys([*names, "sim", "rest"], 0.0)
    for pid, (label, secs) in after.items():
        spent = secs - (before[pid][1] if pid in before and before[pid][0] == label else 0.0)
        part = next((n for n in names if label.startswith(f"{n}-")), None)
        if part is None:
            part = "sim" if label.startswith("chefbot_sim") else "rest"
        parts[part] += max(spent, 0.0)
    return parts


def run_process(site: str, name: str, seed: int = 0, only: int | None = None) -> Drive:
    """One run in a process of its own (rospy joins one master per process).  ``only``: that robot's leg
    alone (index)."""
    cmd = [sys.executable, str(Path(__file__).resolve()), site, name, str(seed)]
    if only is not None:
        cmd.append(f"--only={only}")
    # its own session, stopped with what it started on a timeout or an interrupt (SIGINT first: the run unwinds
    # and stops its launch, which is in a session of its own and would outlive a SIGKILL of the run)
    proc = run_captured(cmd, LEG_TIMEOUT_S + 400)
    start = proc.stdout.find("{")
    if proc.returncode not in (0, 1) or start < 0:
        raise RuntimeError(f"{' '.join(cmd[1:])} failed (exit {proc.returncode}): {proc.stderr[-2000:]}")
    data = json.loads(proc.stdout[start:])
    return Drive([RobotResult(**r) for r in data["robots"]], data["seconds"], data["wall_seconds"], data["cpu"])


def main() -> int:
    stop_on_sigterm()       # SIGTERM unwinds run(): its launch (a session of its own) is stopped, not left running
    args = [a for a in sys.argv[1:] if not a.startswith("--only=") and a != "--keep-logs"]
    only = next((int(a.split("=", 1)[1]) for a in sys.argv[1:] if a.startswith("--only=")), None)
    if len(args) < 2:
        print(__doc__, file=sys.stderr)
        return 2
    site, name = args[0], args[1]
    seed = int(args[2]) if len(args) > 2 else 0
    try:
        legs = scenario(site, name)
        if only is not None:
            legs = [legs[only]]
        drive = run(site, legs, seed, keep_logs="--keep-logs" in sys.argv[1:])
    except (ScenarioError, IndexError) as exc:
        print(f"fleet_scenarios: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print("fleet_scenarios: stopped; the launch and its nodes are stopped", file=sys.stderr)
        return 130
    print(json.dumps({"site": site, "scenario": name, "seed": seed, "seconds": drive.seconds,
                      "wall_seconds": drive.wall_seconds, "cpu": drive.cpu,
                      "robots": [r.__dict__ for r in drive.robots]}, indent=1))
    return 0 if all(r.arrived or r.parked for r in drive.robots) else 1


if __name__ == "__main__":
    sys.exit(main())
