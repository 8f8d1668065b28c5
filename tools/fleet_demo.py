#!/usr/bin/env python3
"""`make demo ROBOTS=N`: several ChefBots deliver in one simulated restaurant (headless).

Starts a private ROS master and ``chefbot_sim fleet_world.launch robots:=N`` (one pybullet world
holding the site fleet file's first N robots, each with its own amcl and move_base under
``/chefbotK``), prints each robot's start, then drives every robot at once: the site's
destinations are split into N runs of neighbouring tables (file order), each run given to the
robot whose parking pose is nearest to it (a minimum-cost assignment), and each robot delivers its
run and returns to its parking pose.  A leg move_base aborts (another robot in the way outside the
single-lane zones, which nothing coordinates yet) is sent again after 5 s, up to 3 times.  One line per leg, prefixed
with the robot's name (path length, time, final ground-truth error, bumper contacts), then
``delivered N/M tables with K robots in T s``.

A table counts as delivered when move_base reports SUCCEEDED and the simulator's ground truth is
within 0.05 m / 0.05 rad of the table pose.  Exit code 0 only when every table was delivered and
every robot is back at its parking pose.  Results also go to build/demo/fleet.json.

Environment (``make demo ROBOTS=3 [FLEET_FILE=...] [WORLD=... MAP=... TABLES_FILE=...]``):
CHEFBOT_DEMO_ROBOTS (N >= 2), CHEFBOT_DEMO_FLEET_FILE (default: the hotel's), CHEFBOT_DEMO_WORLD,
CHEFBOT_DEMO_MAP (the world's raster: the fleet and tables files' poses are in the world frame),
CHEFBOT_DEMO_TABLES_FILE, CHEFBOT_DEMO_TABLES (a comma-separated subset), CHEFBOT_DEMO_DRIVE
(plugin, the default here, or firmware), CHEFBOT_DEMO_USE_IMU (1, the default: odometry heading from the
IMU, as in `make demo`; 0: the wheels'), CHEFBOT_DEMO_RTF (default 1.0).

chefbot_fleet's traffic node lets one robot at a time into each single-lane aisle; elsewhere the
robots only see and avoid each other (chefbot_fleet README), so in tight two-lane space a leg can
still abort and is retried.
"""
from __future__ import annotations

import json
import os
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from procs import ProcessGroup, free_port

ROOT = Path(__file__).resolve().parent.parent
LOG_DIR = ROOT / "build" / "demo"
MAPS = ROOT / "chefbot_navigation" / "maps"
XY_TOL, YAW_TOL = 0.05, 0.05          # m, rad: the acceptance tolerance against ground truth
PARK_TOL = 0.10                       # m: back at the parking pose
STARTUP_TIMEOUT_S = 240.0             # wall time for the sim + N stacks to come up
LEG_TIMEOUT_S = 300.0                 # wall time per leg before giving up
RETRIES = 3                           # a leg move_base aborted (another robot in the way) is sent again ...
RETRY_WAIT_S = 5.0                    # ... after this many sim seconds


class FleetDemoError(ValueError):
    """A bad setting of the fleet demo (names it)."""


def say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


def split_runs(names: list[str], n: int) -> list[list[str]]:
    """``names`` in ``n`` runs of neighbours in file order, sizes differing by at most one."""
    sizes = [len(names) // n + (1 if k < len(names) % n else 0) for k in range(n)]
    out, i = [], 0
    for size in sizes:
        out.append(names[i:i + size])
        i += size
    return out


def assign_runs(runs: list[list[str]], tables: dict, parkings: list) -> list[list[str]]:
    """Run k for robot k: the assignment of runs to robots that minimises the summed distance from each
    robot's parking pose to its run's centroid (scipy's linear_sum_assignment)."""
    from scipy.optimize import linear_sum_assignment

    cost = np.zeros((len(parkings), len(runs)))
    for i, park in enumerate(parkings):
        for j, run in enumerate(runs):
            if run:
                cx = np.mean([tables[t].x for t in run])
                cy = np.mean([tables[t].y for t in run])
                cost[i, j] = np.hypot(cx - park.x, cy - park.y)
    rows, cols = linear_sum_assignment(cost)
    out = [[] for _ in parkings]
    for i, j in zip(rows, cols, strict=True):
        out[i] = runs[j]
    return out


def settings() -> dict:
    """The demo's settings from the environment; FleetDemoError names a bad one."""
    from demo import DemoInputError, table_names

    from chefbot_common.fleet_file import FleetFileError, load_fleet, select
    from chefbot_common.tables import TablesError, load_tables

    try:
        n = int(os.environ.get("CHEFBOT_DEMO_ROBOTS", "2"))
    except ValueError:
        raise FleetDemoError(f"ROBOTS must be a whole number, got {os.environ['CHEFBOT_DEMO_ROBOTS']!r}") from None
    world = os.environ.get("CHEFBOT_DEMO_WORLD", "")
    fleet_file = os.environ.get("CHEFBOT_DEMO_FLEET_FILE", "")
    if world and not fleet_file:
        raise FleetDemoError("WORLD= with ROBOTS= needs FLEET_FILE= too (the robots' start poses in that world)")
    files = {"world": world or str(ROOT / "chefbot_sim" / "worlds" / "hotel.yaml"),
             "map": os.environ.get("CHEFBOT_DEMO_MAP", "") or str(MAPS / "hotel_world_map.yaml"),
             "tables": os.environ.get("CHEFBOT_DEMO_TABLES_FILE", "") or str(MAPS / "hotel_world_tables.yaml"),
             "fleet": fleet_file or str(MAPS / "hotel_fleet.yaml")}
    for key, path in files.items():
        if not Path(path).is_file():
            raise FleetDemoError(f"the {key} file {path} does not exist")
    drive = os.environ.get("CHEFBOT_DEMO_DRIVE", "plugin")
    if drive not in ("plugin", "firmware"):
        raise FleetDemoError(f"DRIVE must be plugin or firmware, got {drive!r}")
    try:
        robots = select(load_fleet(files["fleet"]), n, files["fleet"])
        tables = load_tables(files["tables"])
        names = table_names(tables, files["tables"])      # the destinations, or CHEFBOT_DEMO_TABLES
    except (FleetFileError, TablesError, DemoInputError) as exc:
        raise FleetDemoError(str(exc)) from None
    if n < 2:
        raise FleetDemoError(f"ROBOTS={n}: the fleet demo needs 2 or more robots (one robot: make demo)")
    runs = assign_runs(split_runs(names, n), tables, [r.parking for r in robots])
    return {"files": files, "robots": robots, "tables": tables, "runs": runs, "drive": drive,
            "rtf": os.environ.get("CHEFBOT_DEMO_RTF", "1.0"), "n_tables": len(names),
            "use_imu": os.environ.get("CHEFBOT_DEMO_USE_IMU", "true") not in ("0", "false", "")}


def drive_robot(robot, client, run: list[str], tables: dict, results: dict, lock: threading.Lock) -> None:
    """One robot's route with its ``client`` (delivery.DeliveryClient): its tables, then its parking
    pose (a thread per robot)."""
    import rospy

    try:
        client.wait_ready(120.0)
        client.wait_localized(120.0)
    except (TimeoutError, rospy.ROSException) as exc:   # the robot's stack did not come up
        with lock:
            results[robot.name] = {"error": str(exc), "legs": []}
        say(f"[{robot.name}] ERROR: {exc}")
        return
    legs = []
    for name in [*run, "parking"]:
        pose = robot.parking if name == "parking" else tables[name]
        for attempt in range(1, RETRIES + 2):
            leg = client.deliver(name, pose.x, pose.y, pose.yaw, LEG_TIMEOUT_S)
            if leg.state != "ABORTED" or attempt > RETRIES or rospy.is_shutdown():
                break
            # outside the single-lane zones nothing coordinates the robots: another one may block the
            # way and move on
            say(f"[{robot.name}] {name}: {leg.text}; trying again in {RETRY_WAIT_S:g} s ({attempt}/{RETRIES})")
            rospy.sleep(RETRY_WAIT_S)
        leg.text += f" (attempt {attempt})" if attempt > 1 else ""
        tol_xy = PARK_TOL if name == "parking" else XY_TOL
        within = leg.xy_error <= tol_xy and (name == "parking" or leg.yaw_error <= YAW_TOL)
        leg.ok = leg.ok and within
        legs.append(leg)
        say(f"[{robot.name}] " + ("" if leg.ok else "NOT DONE ") + leg.line())
    with lock:
        results[robot.name] = {"legs": [leg.as_dict() for leg in legs]}


def main() -> int:
    try:
        cfg = settings()
    except FleetDemoError as exc:
        say(f"ERROR: {exc}")
        return 2
    robots, runs = cfg["robots"], cfg["runs"]
    port = free_port()
    uri = f"http://127.0.0.1:{port}"
    env = dict(os.environ, ROS_MASTER_URI=uri, ROS_HOME=str(LOG_DIR / "ros_home"))
    os.environ.update(ROS_MASTER_URI=uri, ROS_HOME=env["ROS_HOME"])
    log = LOG_DIR / "roslaunch.log"
    files = cfg["files"]
    launch_cmd = ["roslaunch", "--wait", "chefbot_sim", "fleet_world.launch", f"robots:={len(robots)}",
                  f"names:={' '.join(r.name for r in robots)}", f"world:={Path(files['world']).resolve()}",
                  f"map_file:={Path(files['map']).resolve()}", f"fleet_file:={Path(files['fleet']).resolve()}",
                  f"drive:={cfg['drive']}", f"real_time_factor:={cfg['rtf']}",
                  f"use_imu:={str(cfg['use_imu']).lower()}"]
    say(f"starting {len(robots)} robots in one simulated {Path(files['world']).stem} ({cfg['drive']} drive; "
        f"master {uri}, real-time factor {cfg['rtf']}); log: {log.relative_to(ROOT)}")
    for r, run in zip(robots, runs, strict=True):
        say(f"  {r.name}: parked at ({r.parking.x:.2f}, {r.parking.y:.2f}); delivers {', '.join(run) or 'nothing'}")
    with ProcessGroup(["roscore", "-p", str(port)], env=env, log=LOG_DIR / "roscore.log"), \
            ProcessGroup(launch_cmd, env=env, log=log) as launch:
        import rosgraph
        import rospy

        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        master = rosgraph.Master("/chefbot_fleet_demo")
        while not (master.is_online() and master.hasParam("/use_sim_time") and master.getParam("/use_sim_time")):
            if time.monotonic() > deadline or launch.poll() is not None:
                say(f"ERROR: the simulation did not come up; see {log}")
                return 1
            time.sleep(0.1)
        rospy.init_node("chefbot_fleet_demo", anonymous=True, disable_signals=True)
        say("waiting for the simulator and every move_base ...")
        lock, results = threading.Lock(), {}
        # the clients are made here, one after the other: each makes a tf2 Buffer, and the first one
        # registers the process's ~tf2_frames service -- made in parallel threads, two could both
        # find it missing and the second registration killed its robot's thread
        from delivery import DeliveryClient
        clients = [DeliveryClient(ns=r.name) for r in robots]
        t0_sim, t0_wall = rospy.Time.now(), time.monotonic()
        def guarded(robot, *args) -> None:
            try:
                drive_robot(robot, *args)
            except Exception as exc:  # noqa: BLE001 -- one robot's failure is reported, the others go on
                say(f"[{robot.name}] ERROR: {type(exc).__name__}: {exc}")
                with lock:
                    results.setdefault(robot.name, {"error": str(exc), "legs": []})

        threads = [threading.Thread(target=guarded, args=(r, c, run, cfg["tables"], results, lock),
                                    daemon=True) for r, c, run in zip(robots, clients, runs, strict=True)]
        for t in threads:
            t.start()
        for t in threads:
            while t.is_alive():
                t.join(0.5)
                if launch.poll() is not None:
                    say(f"ERROR: the simulation stopped (roslaunch exit {launch.poll()}); see {log}")
                    return 1
        sim_s = (rospy.Time.now() - t0_sim).to_sec()
        wall_s = time.monotonic() - t0_wall
        rospy.signal_shutdown("demo done")
    delivered = sum(1 for r in results.values() for leg in r["legs"] if leg["ok"] and leg["name"] != "parking")
    parked = sum(1 for r in results.values() if r["legs"] and r["legs"][-1]["name"] == "parking"
                 and r["legs"][-1]["ok"])
    bumps = sum(leg["bumps"] for r in results.values() for leg in r["legs"])
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    out = LOG_DIR / "fleet.json"
    out.write_text(json.dumps({"robots": len(robots), "real_time_factor": cfg["rtf"], "sim_seconds": sim_s,
                               "wall_seconds": wall_s, "results": results}, indent=2) + "\n")
    say(f"results: {out.relative_to(ROOT)}")
    say(f"back at their parking poses: {parked}/{len(robots)}; bumper contacts: {bumps}")
    say(f"delivered {delivered}/{cfg['n_tables']} tables with {len(robots)} robots in {sim_s:.1f} s "
        f"(sim time; {wall_s:.1f} s wall)")
    return 0 if delivered == cfg["n_tables"] and parked == len(robots) else 1
