"""`make demo SLAM=1`: the book's ch. 4 workflow in one command (issue 16), headless.

Four stages on a private ROS master, one progress line per stage:

1. **map**: ``chefbot_sim gmapping_demo.launch explore:=true`` -- the simulated world, our
   ``slam``, our ``move_base`` on the growing map and ``explore`` driving to frontiers until
   none is left; explore's progress lines (known area, share of the outline closed,
   frontiers left, elapsed sim time) are echoed;
2. **save**: our ``map_saver`` writes the map under the log dir (path printed); it is judged
   against the world raster (TEST ORACLE, judging only: matched / false-occupied / reachable
   free area mapped, and its frame's pose in the world by align_tables' registration), and
   SLAM's live pose, sampled while mapping, against the simulator's truth (error RMS / max
   in the registered frame; ATE after the best rigid fit);
3. **localize**: ``slam`` and ``explore`` are stopped; our ``map_server`` serves the saved
   file and our ``amcl`` starts at SLAM's last ``map -> base_footprint``;
4. **deliver**: the same move_base client and per-leg lines as ``make demo`` to every table
   of the tables file, then home; their poses (world frame) are carried onto the new map
   through the registration, as ``align_tables`` re-marks tables on a new map.

A table counts as delivered when move_base reports SUCCEEDED and ground truth is within
0.10 m / 0.10 rad of it (the manual hotel workflow test's bound; the raster-map demo's is
0.05 m / 0.05 rad).  Exit 0 only when every table was delivered; every failing stage ends
with a message naming it and exit 1; nothing is left running.  Results: build/demo_slam/
(slam_map.yaml/.pgm, slam_demo.json, delivery.json, roslaunch.log, trajectory.json and plots).

Environment (as ``make demo``): CHEFBOT_DEMO_WORLD (world file), CHEFBOT_DEMO_MAP (here: the
world's raster, used for judging only), CHEFBOT_DEMO_TABLES_FILE (tables; the robot starts at
``home``), CHEFBOT_DEMO_TABLES (subset), CHEFBOT_DEMO_RTF, CHEFBOT_DEMO_DRIVE (default here:
plugin, the drive the exploration was measured with), CHEFBOT_DEMO_USE_IMU (default here: 0,
wheel-only heading: with the IMU's drifting yaw one room run came out 2.5 deg rotated, 6.5 % false-occupied),
CHEFBOT_DEMO_SEED (the simulator's sensor- and wheel-noise seed, default 0: another seed, another run),
CHEFBOT_DEMO_SLAM_BAG (a bag path: ``rosbag record`` of scan, tf, tf_static and ground_truth/odom
while mapping, for replaying a run with ``slam_offline``; default: none).
"""
from __future__ import annotations

import contextlib
import json
import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from demo import ROOT, STARTUP_TIMEOUT_S, DemoInputError, say, site_files, table_names
from procs import ProcessGroup, free_port
from slam_workflow import (
    ExploreWatch,
    SlamTrack,
    WorkflowError,
    clear_costmaps,
    judge_map,
    localization_commands,
    save_map,
    slam_pose,
    stop_mapping,
    wait_localized,
)

LOG_DIR = Path(os.environ.get("CHEFBOT_DEMO_SLAM_DIR") or ROOT / "build" / "demo_slam")   # bench_explore: its own
WORLD = ROOT / "chefbot_sim" / "worlds" / "hotel.yaml"
TRUTH_MAP = ROOT / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"
TABLES_FILE = ROOT / "chefbot_navigation" / "maps" / "hotel_world_tables.yaml"
XY_TOL, YAW_TOL = 0.10, 0.10          # m, rad: delivered, by ground truth
EXPLORE_TIMEOUT_S = 2400.0            # wall s for the exploration (explore's own max_duration is 900 s sim)
LEG_TIMEOUT_S = 240.0                 # wall s per delivery leg


def _wait_sim(launch: ProcessGroup, log: Path) -> None:
    """Wait for the master and /use_sim_time (rospy reads it once, in init_node), then init the node."""
    import rosgraph
    import rospy

    deadline = time.monotonic() + STARTUP_TIMEOUT_S
    master = rosgraph.Master("/chefbot_demo")
    while not master.is_online() or not master.hasParam("/use_sim_time") or not master.getParam("/use_sim_time"):
        if time.monotonic() > deadline or launch.poll() is not None:
            raise WorkflowError(f"the simulation did not come up (no /use_sim_time); see {log}")
        time.sleep(0.1)
    rospy.init_node("chefbot_demo", anonymous=True, disable_signals=True)


def run() -> int:
    """The SLAM demo (see the module doc); the process exit code."""
    try:
        env_in = site_files()
    except DemoInputError as exc:
        say(f"ERROR: {exc}")
        return 2
    world = Path(env_in["world"]).resolve() if env_in["world"] else WORLD
    truth_file = Path(env_in["map"]).resolve() if env_in["map"] else TRUTH_MAP
    tables_file = Path(env_in["tables_file"]).resolve() if env_in["tables_file"] else TABLES_FILE
    rtf = os.environ.get("CHEFBOT_DEMO_RTF", "1.0")
    drive = os.environ.get("CHEFBOT_DEMO_DRIVE", "plugin")
    if drive not in ("plugin", "firmware"):
        say(f"ERROR: CHEFBOT_DEMO_DRIVE must be plugin or firmware, got {drive!r}")
        return 2
    use_imu = os.environ.get("CHEFBOT_DEMO_USE_IMU", "false") not in ("0", "false", "")
    seed = os.environ.get("CHEFBOT_DEMO_SEED", "0").strip() or "0"
    if not seed.isdigit():
        say(f"ERROR: CHEFBOT_DEMO_SEED must be a whole number >= 0, got {seed!r}")
        return 2
    from chefbot_common.map_io import MapError, load_map
    from chefbot_common.tables import TablesError, load_map_in_world, load_tables
    try:
        tables = load_tables(tables_file)
        tables_in_world = load_map_in_world(tables_file)
        truth = load_map(truth_file)
    except (TablesError, MapError, OSError) as exc:
        say(f"ERROR: {exc}")
        return 2
    world_pose = {k: tables_in_world.compose(p) for k, p in tables.items()}   # the tables in the world frame
    try:
        names = table_names(tables, tables_file)
    except DemoInputError as exc:
        say(f"ERROR: {exc}")
        return 2
    home = world_pose.get("home")
    if home is None:
        say(f"ERROR: {tables_file} has no 'home' pose (the robot's start)")
        return 2
    port = free_port()
    uri = f"http://127.0.0.1:{port}"
    env = dict(os.environ, ROS_MASTER_URI=uri, ROS_HOME=str(LOG_DIR / "ros_home"))
    os.environ.update(ROS_MASTER_URI=uri, ROS_HOME=env["ROS_HOME"])
    log = LOG_DIR / "roslaunch.log"
    launch_cmd = ["roslaunch", "--wait", "chefbot_sim", "gmapping_demo.launch", "explore:=true",
                  "slam_required:=false", f"world:={world}", f"real_time_factor:={rtf}", f"drive:={drive}",
                  f"use_imu:={str(use_imu).lower()}", f"x:={home.x}", f"y:={home.y}", f"yaw:={home.yaw}",
                  f"seed:={int(seed)}"]
    say(f"SLAM workflow (book ch. 4): map -> save -> localize -> deliver; world {world.name}, {drive} drive"
        f"{', IMU heading' if use_imu else ''}, master {uri}, real-time factor {rtf}; "
        f"log: {log.relative_to(ROOT) if log.is_relative_to(ROOT) else log}")
    say(f"to watch: ROS_MASTER_URI={uri} roslaunch chefbot_gui robot_gui.launch  (or rviz)")
    report: dict = {"world": str(world), "real_time_factor": rtf, "drive": drive, "use_imu": use_imu,
                    "seed": int(seed)}
    LOG_DIR.mkdir(parents=True, exist_ok=True)
    bag = os.environ.get("CHEFBOT_DEMO_SLAM_BAG", "").strip()
    t_wall0 = time.monotonic()
    stage = "start"
    track = None
    try:
        with ProcessGroup(["roscore", "-p", str(port)], env=env, log=LOG_DIR / "roscore.log"), \
                ProcessGroup(launch_cmd, env=env, log=log) as launch:
            _wait_sim(launch, log)
            import rospy

            alive = lambda: launch.poll() is None          # noqa: E731
            track = SlamTrack()                             # SLAM's live pose vs the truth (judging only)
            stage = "map"
            say("stage 1/4 map: slam + explore + move_base explore the world until no frontier is left")
            watch = ExploreWatch()
            t0 = rospy.get_time()
            with contextlib.ExitStack() as recording:
                if bag:
                    recording.enter_context(ProcessGroup(
                        ["rosbag", "record", "-O", bag, "/scan", "/tf", "/tf_static", "/ground_truth/odom"],
                        env=env, log=LOG_DIR / "rosbag_record.log"))
                    say(f"  recording scan, tf, tf_static, ground_truth/odom to {bag}")
                complete = watch.wait(EXPLORE_TIMEOUT_S, alive, echo=lambda line: say(f"  {line}"))
            explore_s = rospy.get_time() - t0
            track.close()
            report.update(explore_sim_s=explore_s, explore_complete=complete, explore_final=watch.final_line())
            watch.close()
            if not complete:
                raise WorkflowError(f"exploration did not complete: {watch.final_line() or 'explore/done false'}")
            stage = "save"
            prefix = LOG_DIR / "slam_map"
            saved = save_map(prefix, env)
            quality, align = judge_map(saved, truth, (home.x, home.y))
            m = align.pose
            say(f"stage 2/4 save: explored in {explore_s:.0f} s sim; map saved to {prefix}.yaml "
                f"({saved.info.width} x {saved.info.height} cells at {saved.info.resolution} m)")
            say(f"  judged against the world raster {truth_file.name}: matched {100 * quality.matched:.1f} %, "
                f"false-occupied {100 * quality.false_occupied:.2f} %, reachable free area mapped "
                f"{100 * quality.coverage:.1f} %; map frame in the world x {m.x:+.3f} m, y {m.y:+.3f} m, "
                f"yaw {m.yaw * 57.2958:+.2f} deg (registration RMS {100 * align.rms_m:.1f} cm)")
            report.update(map_file=f"{prefix}.yaml", matched=quality.matched, false_occupied=quality.false_occupied,
                          coverage=quality.coverage, map_in_world=[m.x, m.y, m.yaw], registration_rms_m=align.rms_m)
            live = track.report(m)
            report.update(live)
            if "live_error_rms_m" in live:
                say(f"  SLAM's live pose against the truth while mapping ({live['track_samples']} samples): "
                    f"{100 * live['live_error_rms_m']:.1f} cm RMS, max {100 * live['live_error_max_m']:.1f} cm "
                    f"at {live['live_error_max_at_s']:.0f} s, heading max {live['live_yaw_error_max_deg']:.1f} deg; "
                    f"ATE after the best rigid fit {100 * live['live_ate_rms_m']:.1f} cm RMS")
            stage = "localize"
            start = slam_pose(track.buffer)
            stop_mapping()
            cmds = localization_commands(prefix.with_suffix(".yaml"), start)
            with ProcessGroup(cmds[0], env=env, log=LOG_DIR / "map_server.log") as server, \
                    ProcessGroup(cmds[1], env=env, log=LOG_DIR / "amcl.log") as amcl:
                both = lambda: alive() and server.poll() is None and amcl.poll() is None   # noqa: E731
                wait_localized(both)
                clear_costmaps()
                say(f"stage 3/4 localize: slam and explore stopped; map_server serves the saved map, amcl started "
                    f"at SLAM's last pose ({start.x:.2f}, {start.y:.2f}) m, {start.yaw * 57.2958:.1f} deg")
                stage = "deliver"
                legs, sim_s, wall_s, trajectory = _deliver(tables, world_pose, names, m, both, log, prefix)
            rospy.signal_shutdown("demo done")
    except WorkflowError as exc:
        say(f"ERROR in stage '{stage}': {exc}; see {log}")
        if track is not None and "live_error_rms_m" not in report:
            report.update(track.report(home), track_frame="home (SLAM's map frame starts at the robot's start)")
        (LOG_DIR / "slam_demo.json").write_text(json.dumps({**report, "failed_stage": stage,
                                                            "error": str(exc)}, indent=2) + "\n")
        return 1
    from delivery import save_route_report
    delivered = sum(1 for leg in legs if leg.ok and leg.name != "home")
    home_leg = next((leg for leg in legs if leg.name == "home"), None)
    report.update(deliver_sim_s=sim_s, legs=[leg.as_dict() for leg in legs], delivered=delivered, tables=len(names))
    (LOG_DIR / "slam_demo.json").write_text(json.dumps(report, indent=2) + "\n")
    summary = {"real_time_factor": rtf, "sim_seconds": sim_s, "wall_seconds": wall_s}
    for line in save_route_report(trajectory, LOG_DIR, legs, summary):
        say(line)
    say(f"back home: {'yes' if home_leg and home_leg.ok else 'NO'}; bumper contacts: {sum(leg.bumps for leg in legs)}")
    say(f"SLAM workflow: explored {report['explore_sim_s']:.0f} s sim, map matched {100 * report['matched']:.1f} % / "
        f"false-occupied {100 * report['false_occupied']:.2f} % / {100 * report['coverage']:.1f} % mapped; "
        f"delivered {delivered}/{len(names)} tables on it in {sim_s:.1f} s sim "
        f"({time.monotonic() - t_wall0:.0f} s wall in all); results: {LOG_DIR / 'slam_demo.json'}")
    return 0 if delivered == len(names) and home_leg is not None and home_leg.ok else 1   # and back home


def _deliver(tables: dict, world_pose: dict, names: list[str], map_in_world, alive, log: Path, prefix: Path):
    """Stage 4: every table, then home, on the saved map; (legs, sim s, wall s, trajectory)."""
    import rospy
    from delivery import DeliveryClient

    client = DeliveryClient(map_in_world)
    try:
        client.wait_ready(60.0)
    except (TimeoutError, rospy.ROSException) as exc:
        raise WorkflowError(str(exc)) from exc
    say(f"stage 4/4 deliver: {len(names)} tables, then home (poses carried onto the new map by the registration)")
    legs = []
    t0_sim, t0_wall = rospy.Time.now(), time.monotonic()
    for name in [*names, "home"]:
        if not alive():
            raise WorkflowError("the simulation, map_server or amcl stopped during the deliveries")
        goal = map_in_world.inverse().compose(world_pose[name])      # world frame -> the saved map's frame
        leg = client.deliver(name, goal.x, goal.y, goal.yaw, LEG_TIMEOUT_S)
        within = leg.xy_error <= XY_TOL and leg.yaw_error <= YAW_TOL
        leg.ok = leg.ok and within
        legs.append(leg)
        off = "" if within or leg.state != "SUCCEEDED" else f" -- outside {XY_TOL} m / {YAW_TOL} rad"
        say(("  " if leg.ok else "  NOT DELIVERED ") + leg.line() + off)
    return (legs, (rospy.Time.now() - t0_sim).to_sec(), time.monotonic() - t0_wall,
            client.trajectory(f"{prefix}.yaml"))
