#!/usr/bin/env python3
"""`make demo`: the main job, headless when there is no display.

Current stage (foundation): bring up the ChefBot model — xacro → robot_description,
robot_state_publisher and joint_state_publisher — on a private ROS master, wait
until every frame of the robot is on /tf + /tf_static, print the TF tree and the
key dimensions read back from the model, and shut everything down.
(Later stages replace this with the simulated hotel delivery.)

Exit code 0 only when the whole tree came up; no process is left behind,
Ctrl-C included.
"""
from __future__ import annotations

import os
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from procs import ProcessGroup, free_port

ROOT = Path(__file__).resolve().parent.parent
LOG_DIR = ROOT / "build" / "demo"
REQUIRED_FRAMES = [
    "base_footprint", "base_link", "wheel_left_link", "wheel_right_link",
    "camera_link", "camera_depth_frame", "camera_depth_optical_frame",
    "camera_rgb_frame", "camera_rgb_optical_frame", "gyro_link", "ultrasonic_link",
]
TIMEOUT_S = 60.0


def say(msg: str) -> None:
    print(f"[demo] {msg}", flush=True)


def print_tree(parents: dict[str, str]) -> None:
    """Print frames as an indented tree from their parent map."""
    children: dict[str, list[str]] = {}
    for child, parent in parents.items():
        children.setdefault(parent, []).append(child)
    roots = sorted({p for p in parents.values() if p not in parents})

    def walk(frame: str, prefix: str, last: bool, top: bool) -> None:
        print(("" if top else prefix + ("└── " if last else "├── ")) + frame)
        kids = sorted(children.get(frame, []))
        for i, kid in enumerate(kids):
            walk(kid, prefix + ("" if top else ("    " if last else "│   ")), i == len(kids) - 1, False)

    for r in roots:
        walk(r, "", True, True)


def main() -> int:
    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOME=str(LOG_DIR / "ros_home"))
    os.environ.update(ROS_MASTER_URI=env["ROS_MASTER_URI"], ROS_HOME=env["ROS_HOME"])
    cmd = ["roslaunch", "-p", str(port), "--wait", "chefbot_description", "view_model.launch", "rviz:=false"]
    log = LOG_DIR / "roslaunch.log"
    say(f"starting the robot model on a private master (port {port}); log: {log.relative_to(ROOT)}")
    with ProcessGroup(["roscore", "-p", str(port)], env=env, log=LOG_DIR / "roscore.log"), \
            ProcessGroup(cmd, env=env, log=log) as launch:
        import rosgraph
        import rospy
        import tf2_ros
        import yaml

        deadline = time.monotonic() + TIMEOUT_S
        while not rosgraph.Master("/chefbot_demo").is_online():
            if time.monotonic() > deadline:
                say("ERROR: the ROS master did not come up")
                return 1
            time.sleep(0.1)
        rospy.init_node("chefbot_demo", anonymous=True, disable_signals=True)
        buf = tf2_ros.Buffer()
        tf2_ros.TransformListener(buf)
        parents: dict[str, str] = {}
        say("waiting for the robot's frames on /tf and /tf_static ...")
        while time.monotonic() < deadline:
            if launch.poll() is not None:
                say(f"ERROR: roslaunch exited ({launch.poll()}); see {log}")
                print(log.read_text(errors="replace")[-3000:])
                return 1
            frames = yaml.safe_load(buf.all_frames_as_yaml()) or {}
            parents = {f: d["parent"] for f, d in frames.items()}
            if all(f in parents or f == "base_footprint" for f in REQUIRED_FRAMES) and parents:
                break
            time.sleep(0.2)
        else:
            missing = [f for f in REQUIRED_FRAMES if f not in parents and f != "base_footprint"]
            say(f"ERROR: frames missing after {TIMEOUT_S:.0f} s: {missing}")
            return 1
        say(f"TF tree ({len(parents) + 1} frames):")
        print_tree(parents)
        from chefbot_description import model
        robot = model.parse_urdf(rospy.get_param("robot_description"))
        wheels = model.wheel_geometry(robot)
        say(f"model read back from robot_description: {len(robot.links)} links, "
            f"{model.total_mass(robot):.2f} kg, wheel radius {wheels.radius:.3f} m, "
            f"wheel separation {wheels.separation:.3f} m")
        rospy.signal_shutdown("demo done")
    say("done: the robot model is complete and every frame is published")
    return 0


if __name__ == "__main__":
    try:
        sys.exit(main())
    except KeyboardInterrupt:
        say("interrupted; everything stopped")
        sys.exit(130)
