#!/usr/bin/env python3
"""`make demo ROBOTS=N`: a stream of orders served by several ChefBots in one simulated restaurant.

Starts a private ROS master, ``chefbot_sim fleet_world.launch robots:=N`` (one pybullet world holding
the site fleet file's first N robots, each with its own amcl and move_base under ``/chefbotK``) and
``chefbot_fleet dispatcher.launch`` (the order queue, on a fresh database under build/demo), waits
until every robot reports idle, then places a seeded stream of orders on the dispatcher's
``/fleet/deliver`` action: ``ORDERS`` orders (default: as many as the site has tables) of one or two
tables, Poisson arrivals every ``ORDER_EVERY`` s of sim time on average.  The dispatcher plans them
onto trips (up to 3 orders loaded at the kitchen per trip) and drives the robots.  One line per order
when it ends (tables, robot, wait from the order to the robot at its last table, the robot's
ground-truth distance to that table), then the throughput summary: orders per hour, median and
95th-percentile wait, makespan, bumper contacts, robots back at their parking poses.  With a display
(or CHEFBOT_DEMO_GUI=1; CHEFBOT_DEMO_GUI=0: never) the fleet window (``chefbot_gui fleet_gui.launch``)
shows the robots on the map and the queue while the stream runs.

An order counts as delivered when the dispatcher reports it served and the simulator's ground truth
puts its robot within 0.05 m of one of the order's tables at that moment.  Exit code 0 only when every
order was delivered, no bumper was pressed and every robot is back at its parking pose.  Results also
go to build/demo/fleet.json.  The demo waits as long as orders keep being placed or ending (a long
backlog is served to its end); it gives up, naming the unfinished orders, when none was placed or
ended for 15 min of sim time (a robot's trip is a few minutes), when the sim clock stood still for
2 min of wall time, or when the launch ends: a loaded machine that runs the sim at a tenth of real
time is slow, not stalled.

Environment (``make demo ROBOTS=3 [FLEET_FILE=...] [WORLD=... MAP=... TABLES_FILE=...]``):
CHEFBOT_DEMO_ROBOTS (N >= 2), CHEFBOT_DEMO_FLEET_FILE (default: the hotel's; it names the kitchen),
CHEFBOT_DEMO_WORLD, CHEFBOT_DEMO_MAP (the world's raster: the fleet and tables files' poses are in the
world frame), CHEFBOT_DEMO_TABLES_FILE, CHEFBOT_DEMO_TABLES (a comma-separated subset), CHEFBOT_DEMO_DRIVE
(plugin, the default here, or firmware), CHEFBOT_DEMO_USE_IMU (1, the default: odometry heading from the
IMU, as in `make demo`; 0: the wheels'), CHEFBOT_DEMO_RTF (default 1.0), CHEFBOT_DEMO_ORDERS,
CHEFBOT_DEMO_ORDER_EVERY (s, default 20), CHEFBOT_DEMO_SEED (default 0), CHEFBOT_DEMO_POLICY (the
dispatcher's: insertion, the default, or nearest_idle, the baseline), CHEFBOT_DEMO_DIR (results and
logs; default build/demo).  Run directly (``python tools/fleet_demo.py``) it also takes ROBOTS=1: the
one-robot reference of chefbot_fleet's bench_fleet_stream (``make demo ROBOTS=1`` is the plain demo).
"""
from __future__ import annotations

import json
import math
import os
import random
import sys
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parent))
from procs import ProcessGroup, free_port, stop_on_sigterm

ROOT = Path(__file__).resolve().parent.parent
LOG_DIR = Path(os.environ.get("CHEFBOT_DEMO_DIR", "") or ROOT / "build" / "demo")
MAPS = ROOT / "chefbot_navigation" / "maps"
XY_TOL = 0.05                         # m: the serving robot against the table pose, ground truth
PARK_TOL = 0.10                       # m: back at the parking pose
STARTUP_TIMEOUT_S = 300.0             # wall time for the sim, N stacks and the dispatcher to come up
ORDER_STALL_S = 900.0                 # sim time without an order placed or ended before the demo gives up
CLOCK_STALL_S = 120.0                 # wall time with the sim clock standing still before the demo gives up
                                      # (a hang; a long backlog of orders still being served is not one)
FINAL = ("served", "cancelled", "failed")


class FleetDemoError(ValueError):
    """A bad setting of the fleet demo (names it)."""


def say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


def shown(path: Path) -> str:
    """``path`` as the progress lines show it: relative to the workspace when inside it, else whole
    (``CHEFBOT_DEMO_DIR`` may be any directory, e.g. a benchmark's temporary one)."""
    try:
        return str(path.relative_to(ROOT))
    except ValueError:
        return str(path)


def order_stream(tables: list[str], count: int, every_s: float, seed: int) -> list[tuple[float, list[str]]]:
    """``count`` orders of one or two distinct ``tables`` (uniform), at Poisson arrival times with mean
    gap ``every_s`` s, the first at 0: [(t, tables)], seeded."""
    if count < 1 or not tables or not every_s > 0:
        raise FleetDemoError(f"an order stream needs orders >= 1, tables and a gap > 0 (got {count}, "
                             f"{len(tables)} tables, {every_s})")
    rng = random.Random(seed)
    t, out = 0.0, []
    for k in range(count):
        if k:
            t += rng.expovariate(1.0 / every_s)
        n = 1 if len(tables) < 2 else rng.choice((1, 2))
        out.append((round(t, 1), rng.sample(tables, n)))
    return out


def summarise(orders: list[dict], robots: int) -> dict:
    """The stream's figures from the per-order results (each with ``placed``, ``ended`` sim s, ``ok``)."""
    done = [o for o in orders if o["ok"]]
    waits = sorted(o["ended"] - o["placed"] for o in done)
    start = min((o["placed"] for o in orders), default=0.0)
    end = max((o["ended"] for o in orders if o["ended"] is not None), default=start)
    makespan = end - start
    pct = (lambda q: float(waits[min(len(waits) - 1, max(0, math.ceil(q / 100 * len(waits)) - 1))])) if waits \
        else (lambda q: float("nan"))
    return {"robots": robots, "orders": len(orders), "delivered": len(done), "makespan_s": makespan,
            "orders_per_hour": len(done) / makespan * 3600.0 if makespan > 0 else 0.0,
            "wait_mean_s": float(np.mean(waits)) if waits else float("nan"),
            "wait_median_s": float(np.median(waits)) if waits else float("nan"), "wait_p95_s": pct(95)}


def load_site(files: dict, n: int) -> tuple[list, dict, list[str]]:
    """The site of a fleet run (shared with tools/fleet_soak.py): ``files`` (world, map, tables, fleet
    paths) checked to exist, the fleet file's first ``n`` robots (n >= 1; the file must name a kitchen),
    the tables and the destination table names (CHEFBOT_DEMO_TABLES, or every table).
    FleetDemoError names what is wrong."""
    from demo import DemoInputError, table_names

    from chefbot_common.fleet_file import FleetFileError, load_fleet, load_kitchen, select
    from chefbot_common.tables import TablesError, load_tables

    for key, path in files.items():
        if not Path(path).is_file():
            raise FleetDemoError(f"the {key} file {path} does not exist")
    try:
        robots = select(load_fleet(files["fleet"]), n, files["fleet"])
        if load_kitchen(files["fleet"]) is None:
            raise FleetDemoError(f"{files['fleet']} has no kitchen pose: the dispatcher's robots load there "
                                 "(chefbot_fleet README, 'Fleet files')")
        tables = load_tables(files["tables"])
        names = table_names(tables, files["tables"])      # the destinations, or CHEFBOT_DEMO_TABLES
    except (FleetFileError, TablesError, DemoInputError) as exc:
        raise FleetDemoError(str(exc)) from None
    if n < 1:
        raise FleetDemoError(f"ROBOTS={n}: a fleet run needs 1 or more robots")
    return robots, tables, names


def site_files(world: str = "", fleet_file: str = "", map_file: str = "", tables_file: str = "") -> dict:
    """The world, map, tables and fleet files of a fleet run: the hotel's unless given; a world needs its
    fleet file (the robots' start poses in it)."""
    if world and not fleet_file:
        raise FleetDemoError("WORLD= with ROBOTS= needs FLEET_FILE= too (the robots' start poses in that world)")
    return {"world": world or str(ROOT / "chefbot_sim" / "worlds" / "hotel.yaml"),
            "map": map_file or str(MAPS / "hotel_world_map.yaml"),
            "tables": tables_file or str(MAPS / "hotel_world_tables.yaml"),
            "fleet": fleet_file or str(MAPS / "hotel_fleet.yaml")}


def settings() -> dict:
    """The demo's settings from the environment; FleetDemoError names a bad one."""

    def number(name: str, default: str, kind=int):
        raw = os.environ.get(name, default)
        try:
            return kind(raw)
        except ValueError:
            raise FleetDemoError(f"{name.replace('CHEFBOT_DEMO_', '')} must be a number, got {raw!r}") from None

    try:
        n = int(os.environ.get("CHEFBOT_DEMO_ROBOTS", "2"))
    except ValueError:
        raise FleetDemoError(f"ROBOTS must be a whole number, got {os.environ['CHEFBOT_DEMO_ROBOTS']!r}") from None
    if n < 1:
        raise FleetDemoError(f"ROBOTS={n}: the fleet demo needs 1 or more robots")
    files = site_files(os.environ.get("CHEFBOT_DEMO_WORLD", ""), os.environ.get("CHEFBOT_DEMO_FLEET_FILE", ""),
                       os.environ.get("CHEFBOT_DEMO_MAP", ""), os.environ.get("CHEFBOT_DEMO_TABLES_FILE", ""))
    drive = os.environ.get("CHEFBOT_DEMO_DRIVE", "plugin")
    if drive not in ("plugin", "firmware"):
        raise FleetDemoError(f"DRIVE must be plugin or firmware, got {drive!r}")
    robots, tables, names = load_site(files, n)
    policy = os.environ.get("CHEFBOT_DEMO_POLICY", "insertion")
    if policy not in ("insertion", "nearest_idle"):
        raise FleetDemoError(f"POLICY must be insertion or nearest_idle, got {policy!r}")
    count = number("CHEFBOT_DEMO_ORDERS", str(len(names)))
    every = number("CHEFBOT_DEMO_ORDER_EVERY", "20", float)
    stream = order_stream(names, count, every, number("CHEFBOT_DEMO_SEED", "0"))
    return {"files": files, "robots": robots, "tables": tables, "stream": stream, "drive": drive, "policy": policy,
            "rtf": os.environ.get("CHEFBOT_DEMO_RTF", "1.0"),
            "use_imu": os.environ.get("CHEFBOT_DEMO_USE_IMU", "true") not in ("0", "false", "")}


class Watch:
    """Ground truth and bumpers of every robot, and the dispatcher's queue (the demo's judge)."""

    def __init__(self, names: list[str], tables: dict) -> None:
        import rospy
        from nav_msgs.msg import Odometry
        from std_msgs.msg import Bool

        from chefbot_fleet.msg import OrderQueue

        self.tables, self.lock = tables, threading.Lock()
        self.truth: dict[str, tuple[float, float]] = {}
        self.metres = {n: 0.0 for n in names}           # ground-truth distance driven
        self.bumps = {n: 0 for n in names}              # bumper messages reading pressed (20 Hz)
        self.contacts = {n: 0 for n in names}           # presses (released -> pressed)
        self._pressed = {n: False for n in names}
        self.states: dict[str, list[str]] = {}          # order id -> its states in the order published
        self.queue = None
        self.served_at: dict[str, float] = {}          # order id -> robot's distance to its nearest table
        for n in names:
            rospy.Subscriber(f"/{n}/ground_truth/odom", Odometry, self._on_truth, callback_args=n, queue_size=10)
            rospy.Subscriber(f"/{n}/bumper", Bool, self._on_bumper, callback_args=n, queue_size=10)
        rospy.Subscriber("/fleet/orders", OrderQueue, self._on_queue, queue_size=20)

    def _on_truth(self, m, name: str) -> None:
        with self.lock:
            here = (m.pose.pose.position.x, m.pose.pose.position.y)
            if name in self.truth:
                self.metres[name] += math.dist(self.truth[name], here)
            self.truth[name] = here

    def _on_bumper(self, m, name: str) -> None:
        with self.lock:
            if m.data:
                self.bumps[name] += 1
                self.contacts[name] += not self._pressed[name]
            self._pressed[name] = bool(m.data)

    def _on_queue(self, m) -> None:
        with self.lock:
            self.queue = m
            for o in m.orders:
                seen = self.states.setdefault(o.id, [])
                if not seen or seen[-1] != o.state:
                    seen.append(o.state)
                if o.state == "served" and o.id not in self.served_at and o.assigned in self.truth:
                    x, y = self.truth[o.assigned]
                    self.served_at[o.id] = min(math.hypot(x - self.tables[t].x, y - self.tables[t].y)
                                               for t in o.tables)

    def robots(self) -> dict:
        with self.lock:
            return {r.name: r for r in self.queue.robots} if self.queue else {}

    def orders(self) -> dict:
        with self.lock:
            return {o.id: o for o in self.queue.orders} if self.queue else {}


def place_orders(cfg: dict, watch: Watch, log: Path, launch) -> list[dict]:
    """Place the stream on /fleet/deliver at its sim times; one line per order as it is placed and as it
    ends (once the dispatcher's queue shows it final, so the robot's place then is known)."""
    import actionlib
    import rospy
    from actionlib_msgs.msg import GoalStatus

    from chefbot_fleet.msg import DeliverAction, DeliverGoal

    client = actionlib.ActionClient("/fleet/deliver", DeliverAction)
    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    while not (client.wait_for_server(rospy.Duration(0.1)) and len(watch.robots()) == len(cfg["robots"])
               and all(r.state == "idle" for r in watch.robots().values())):
        if time.monotonic() > deadline or launch.poll() is not None:
            raise TimeoutError(f"the dispatcher or a robot did not come up; see {log}")
        time.sleep(0.2)
    say(f"every robot idle; placing {len(cfg['stream'])} orders over {cfg['stream'][-1][0]:.0f} s")
    t0 = rospy.get_time()
    todo = list(enumerate(cfg["stream"]))
    pending: dict[int, dict] = {}        # stream index -> {tables, placed, gh, id, ended_at}
    results: list[dict] = []
    ended = (GoalStatus.SUCCEEDED, GoalStatus.ABORTED, GoalStatus.PREEMPTED, GoalStatus.REJECTED,
             GoalStatus.RECALLED)
    progress = t0                        # sim time an order was last placed or ended
    clock = (t0, time.monotonic())       # the sim clock's last reading that differed, and its wall time
    while todo or pending:
        now = rospy.get_time()
        if now > clock[0]:
            clock = (now, time.monotonic())
        why = None
        if now - progress > ORDER_STALL_S:
            why = f"no order placed or ended for {ORDER_STALL_S:.0f} s (sim)"
        elif time.monotonic() - clock[1] > CLOCK_STALL_S:
            why = f"the sim clock stood still at {now - t0:.1f} s for {CLOCK_STALL_S:.0f} s (wall)"
        elif launch.poll() is not None:
            why = f"roslaunch ended (exit {launch.poll()})"
        if why is not None:
            say(f"ERROR: {len(pending) + len(todo)} order(s) not finished: {why}; see {log}")
            break
        while todo and now >= t0 + todo[0][1][0]:
            k, (_, tables) = todo.pop(0)
            pending[k] = {"tables": tables, "placed": now, "id": "",
                          "gh": client.send_goal(DeliverGoal(tables=tables, priority=1.0)), "ended_at": None}
            progress = now
        for k, o in list(pending.items()):
            status = o["gh"].get_goal_status()
            if not o["id"] and status == GoalStatus.ACTIVE:
                o["id"] = o["gh"].get_goal_status_text().split()[-1]        # "order o7"
                say(f"{o['id']} placed at {o['placed'] - t0:6.1f} s: {', '.join(o['tables'])}")
            if status not in ended:
                continue
            result = o["gh"].get_result()
            oid = result.order_id if result is not None and result.order_id else o["id"] or "?"
            order = watch.orders().get(oid)
            o["ended_at"] = o["ended_at"] or time.monotonic()
            if status != GoalStatus.REJECTED and (order is None or order.state not in FINAL) \
                    and time.monotonic() - o["ended_at"] < 5.0:
                continue                 # the queue's publication of it follows the action's result
            end_t = order.updated.to_sec() if order is not None else rospy.get_time()
            dist = watch.served_at.get(oid, math.inf)
            state = result.state if result is not None and result.state else "rejected"
            ok = state == "served" and dist <= XY_TOL
            robot = (order.assigned if order is not None else "") or "-"
            reason = result.reason if result is not None and result.reason else o["gh"].get_goal_status_text()
            say(f"{oid} {'+'.join(o['tables'])}: " + ("" if ok else "NOT DONE ") +
                f"{state} by {robot}, wait {end_t - o['placed']:.1f} s, at table {dist:.3f} m" +
                (f" ({reason})" if state != "served" and reason else ""))
            results.append({"id": oid, "tables": o["tables"], "robot": robot, "state": state,
                            "placed": o["placed"], "ended": end_t, "at_table_m": dist if math.isfinite(dist) else None,
                            "ok": ok})
            del pending[k]
            progress = now
        time.sleep(0.1)
    for o in pending.values():
        results.append({"id": o["id"] or "?", "tables": o["tables"], "robot": "-", "state": "unfinished",
                        "placed": o["placed"], "ended": None, "at_table_m": None, "ok": False})
    for _, (_, tables) in todo:
        results.append({"id": "?", "tables": tables, "robot": "-", "state": "not placed", "placed": t0,
                        "ended": None, "at_table_m": None, "ok": False})
    return results


def main() -> int:
    try:
        cfg = settings()
    except FleetDemoError as exc:
        say(f"ERROR: {exc}")
        return 2
    robots = cfg["robots"]
    port = free_port()
    uri = f"http://127.0.0.1:{port}"
    env = dict(os.environ, ROS_MASTER_URI=uri, ROS_HOME=str(LOG_DIR / "ros_home"))
    os.environ.update(ROS_MASTER_URI=uri, ROS_HOME=env["ROS_HOME"])
    log = LOG_DIR / "roslaunch.log"
    files = cfg["files"]
    names = [r.name for r in robots]
    database = LOG_DIR / "orders.sqlite"
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    database.unlink(missing_ok=True)                 # every demo starts with an empty queue
    launch_cmd = ["roslaunch", "--wait", "chefbot_sim", "fleet_world.launch", f"robots:={len(robots)}",
                  f"names:={' '.join(names)}", f"world:={Path(files['world']).resolve()}",
                  f"map_file:={Path(files['map']).resolve()}", f"fleet_file:={Path(files['fleet']).resolve()}",
                  f"drive:={cfg['drive']}", f"real_time_factor:={cfg['rtf']}",
                  f"use_imu:={str(cfg['use_imu']).lower()}"]
    dispatcher_cmd = ["roslaunch", "--wait", "chefbot_fleet", "dispatcher.launch", f"robots:={' '.join(names)}",
                      f"fleet_file:={Path(files['fleet']).resolve()}",
                      f"tables_file:={Path(files['tables']).resolve()}", f"database:={database}",
                      f"policy:={cfg['policy']}"]
    from demo import gui_mode  # the same rule as `make demo`: a display, or GUI=1
    gui = gui_mode()
    gui_cmd = ["roslaunch", "--wait", "chefbot_gui", "fleet_gui.launch",
               f"fleet_file:={Path(files['fleet']).resolve()}", f"tables_file:={Path(files['tables']).resolve()}",
               "required:=false"]
    if gui:
        say(f"the fleet window shows the robots and the queue (log: {shown(LOG_DIR / 'fleet_gui.log')}); "
            "staff's orders placed in it are served too, but only the stream's are judged")
    say(f"starting {len(robots)} robots in one simulated {Path(files['world']).stem} ({cfg['drive']} drive; "
        f"master {uri}, real-time factor {cfg['rtf']}) and the dispatcher; log: {shown(log)}")
    say(f"the order stream: {len(cfg['stream'])} orders of one or two tables over {cfg['stream'][-1][0]:.0f} s "
        "of sim time (seeded)")
    with ProcessGroup(["roscore", "-p", str(port)], env=env, log=LOG_DIR / "roscore.log"), \
            ProcessGroup(launch_cmd, env=env, log=log) as launch:
        import rosgraph

        deadline = time.monotonic() + STARTUP_TIMEOUT_S
        master = rosgraph.Master("/chefbot_fleet_demo")
        while not (master.is_online() and master.hasParam("/use_sim_time") and master.getParam("/use_sim_time")):
            if time.monotonic() > deadline or launch.poll() is not None:
                say(f"ERROR: the simulation did not come up; see {log}")
                return 1
            time.sleep(0.1)
        # the dispatcher only now: a node reads /use_sim_time once, at start (before it, wall time)
        with ProcessGroup(dispatcher_cmd, env=env, log=LOG_DIR / "dispatcher.log"), \
                ProcessGroup(gui_cmd if gui else ["true"], env=env, log=LOG_DIR / "fleet_gui.log"):
            code = run_stream(cfg, robots, names, launch, log)
    return code


def run_stream(cfg: dict, robots: list, names: list[str], launch, log: Path) -> int:
    """With the simulation and the dispatcher up: the order stream, the robots back home, the figures."""
    import rospy

    rospy.init_node("chefbot_fleet_demo", anonymous=True, disable_signals=True)
    say("waiting for the simulator, every robot's stack and the dispatcher ...")
    watch = Watch(names, cfg["tables"])
    t0_wall = time.monotonic()
    try:
        results = place_orders(cfg, watch, log, launch)
    except (TimeoutError, RuntimeError) as exc:
        say(f"ERROR: {exc}")
        return 1
    # back to their parking poses
    deadline = time.monotonic() + 300.0
    while not all(r.state == "idle" for r in watch.robots().values()) and time.monotonic() < deadline \
            and launch.poll() is None:
        time.sleep(0.2)
    time.sleep(0.5)
    parked = sum(1 for r in robots if r.name in watch.truth
                 and math.hypot(watch.truth[r.name][0] - r.parking.x, watch.truth[r.name][1] - r.parking.y) <= PARK_TOL)
    wall_s = time.monotonic() - t0_wall
    rospy.signal_shutdown("demo done")
    figures = summarise(results, len(robots))
    out = LOG_DIR / "fleet.json"
    with watch.lock:
        bumps = sum(watch.bumps.values())
        served_twice = sorted(i for i, seen in watch.states.items() if seen.count("served") > 1)
        metres = dict(watch.metres)
    lost = [o["id"] for o in results if o["state"] in ("unfinished", "not placed")]
    figures.update(km=sum(metres.values()) / 1000.0, served_twice=len(served_twice), lost=len(lost),
                   contacts=bumps, policy=cfg["policy"], sim_per_wall=figures["makespan_s"] / max(wall_s, 1e-9))
    out.write_text(json.dumps({"real_time_factor": cfg["rtf"], "wall_seconds": wall_s, "summary": figures,
                               "bumper_contacts": watch.bumps, "metres": metres, "served_twice": served_twice,
                               "lost": lost, "parked": parked, "orders": results}, indent=2) + "\n")
    say(f"results: {shown(out)}")
    say(f"back at their parking poses: {parked}/{len(robots)}; bumper contacts: {bumps}")
    say(f"delivered {figures['delivered']}/{figures['orders']} orders with {len(robots)} robots in "
        f"{figures['makespan_s']:.1f} s (sim time; {wall_s:.1f} s wall): {figures['orders_per_hour']:.1f} orders/h, "
        f"wait median {figures['wait_median_s']:.1f} s, 95th percentile {figures['wait_p95_s']:.1f} s")
    ok = figures["delivered"] == figures["orders"] and parked == len(robots) and bumps == 0 and not served_twice
    return 0 if ok else 1


if __name__ == "__main__":
    stop_on_sigterm()             # run directly (bench_fleet_stream): SIGTERM stops every group it started
    sys.exit(main())
