"""Latency of the robot-PC chain: a cmd_vel step until the board applies a motor command.

Runs the unmodified robot_standalone.launch (twist_to_motors → pid_velocity →
launchpad_node → serial) on a private master against the virtual LaunchPad on
a real pty (our firmware core), publishes cmd_vel steps and timestamps the
moment the firmware's parser accepts the first non-zero ``s`` command.  It runs
the chain twice in one go: ``event_driven:=false`` (the book's timer-only chain,
"before": each hop waits for its timer, 1/50 + 1/30 + 1/30 s worst case) and
the default event-driven chain ("after": each hop acts on a new command in the
callback that received it).  The reference is the physical floor: sending one
``s`` line at 115 200 baud (10 bits per byte).

``run()`` re-executes this file in a subprocess (rospy allows one node per
process) and reads its JSON.
"""
from __future__ import annotations

import json
import os
import statistics
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
sys.path.insert(0, str(ROOT / "tools"))
from procs import ProcessGroup, free_port, run_captured, stop_on_sigterm  # noqa: E402  (stdlib only)

TIMER_BOUND_MS = (1 / 50 + 1 / 30 + 1 / 30) * 1000   # twist_to_motors, pid_velocity, launchpad_node periods
# one motor command "s -1023 -1023 *XX\r" on the wire: 19 bytes x 10 bits at 115 200 baud
SERIAL_FLOOR_MS = 19 * 10 / 115200 * 1000
GOAL_MS = {"median": 10.0, "p90": 15.0}


def measure(trials: int, event_driven: bool = True) -> dict:
    import rosgraph
    import rospy
    from geometry_msgs.msg import Twist

    from chefbot_firmware.virtual_board import VirtualBoard

    port = free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}")
    os.environ["ROS_MASTER_URI"] = env["ROS_MASTER_URI"]
    tmpdir = tempfile.TemporaryDirectory(prefix="chefbot_bench_")
    tmp = Path(tmpdir.name)
    link = tmp / "launchpad"
    board = VirtualBoard(link)
    lock = threading.Lock()
    first_nonzero: list[float] = []
    stop = threading.Event()

    def step_board() -> None:
        last = time.monotonic()
        while not stop.is_set():
            time.sleep(0.0005)
            now = time.monotonic()
            with lock:
                board.step(now - last)
                if board.fw.command(0) != 0 and not first_nonzero:
                    first_nonzero.append(now)
            last = now

    thread = threading.Thread(target=step_board, daemon=True)
    thread.start()
    launch = ["roslaunch", "--wait", "chefbot_bringup", "robot_standalone.launch", f"port:={link}",
              "use_sonar:=false", "cliff_guard:=false", f"event_driven:={str(event_driven).lower()}"]
    latencies: list[float] = []
    try:
        with ProcessGroup(["roscore", "-p", str(port)], env=env, log=tmp / "roscore.log"), \
                ProcessGroup(launch, env=env, log=tmp / "launch.log"):
            deadline = time.monotonic() + 60
            while not rosgraph.Master("/bench").is_online():
                if time.monotonic() > deadline:
                    raise RuntimeError("no ROS master")
                time.sleep(0.1)
            rospy.init_node("latency_bench", disable_signals=True)
            pub = rospy.Publisher("cmd_vel", Twist, queue_size=1, tcp_nodelay=True)
            while pub.get_num_connections() == 0:
                if time.monotonic() > deadline:
                    raise RuntimeError("twist_to_motors did not subscribe to cmd_vel")
                time.sleep(0.05)
            go, halt = Twist(), Twist()
            go.linear.x = 0.2
            for k in range(trials):
                # idle: wait until the board applies 0, then a little longer so timers are at random phase
                t_idle = time.monotonic() + 5
                while True:
                    with lock:
                        idle = board.fw.command(0) == 0
                    if idle or time.monotonic() > t_idle:
                        break
                    pub.publish(halt)
                    time.sleep(0.02)
                time.sleep(0.3 + 0.013 * (k % 7))
                with lock:
                    first_nonzero.clear()
                t0 = time.monotonic()
                pub.publish(go)
                while time.monotonic() - t0 < 2.0:
                    with lock:
                        hit = first_nonzero[0] if first_nonzero else None
                    if hit is not None:
                        latencies.append((hit - t0) * 1000)
                        break
                    time.sleep(0.001)
                pub.publish(halt)
            rospy.signal_shutdown("bench done")
    finally:
        stop.set()
        thread.join(timeout=2)
        board.close()
        tmpdir.cleanup()
    return {"trials": trials, "latencies_ms": latencies}


def latencies(trials: int, event_driven: bool) -> list[float]:
    """Sorted latencies (ms) of ``trials`` cmd_vel steps, measured in a fresh subprocess."""
    cmd = [sys.executable, __file__, "--measure", str(trials), "event" if event_driven else "timer"]
    out = run_captured(cmd, timeout=600)
    if out.returncode != 0:
        raise RuntimeError(f"latency bench failed:\n{out.stderr[-2000:]}")
    lat = sorted(json.loads(out.stdout.strip().splitlines()[-1])["latencies_ms"])
    if len(lat) < trials * 0.9:
        raise RuntimeError(f"only {len(lat)} of {trials} steps reached the board")
    return lat


def run(quick: bool = False) -> list[dict]:
    trials = 10 if quick else 40
    rows = []
    for event_driven, label in ((False, "before: timer-only chain"), (True, "after: event-driven chain")):
        lat = latencies(trials, event_driven)
        stats = {"median": statistics.median(lat), "p90": lat[int(0.9 * (len(lat) - 1))]}
        for key, name in (("median", "median"), ("p90", "90th percentile")):
            goal = GOAL_MS[key] if event_driven else None
            rows.append({"bench": "bringup latency",
                         "case": f"cmd_vel step -> board 's', {label} ({len(lat)} steps, {name})",
                         "metric": "ms", "ours": stats[key], "reference": SERIAL_FLOOR_MS,
                         "reference_name": "1 command at 115200 baud",
                         "goal": f"<= {goal:g} ms" if goal else f"timer bound {TIMER_BOUND_MS:.0f} ms",
                         "met": stats[key] <= goal if goal else None})
    return rows


if __name__ == "__main__":
    if len(sys.argv) == 4 and sys.argv[1] == "--measure":
        stop_on_sigterm()
        print(json.dumps(measure(int(sys.argv[2]), event_driven=sys.argv[3] == "event")))
    else:
        for r in run(quick="--quick" in sys.argv):
            print(r)
