"""tools/fleet_scenarios.py's pure parts: the shipped scenarios are usable, bad ones are refused by name; the CPU
of a run is split by robot stack, simulator and the rest (tools/procs.tree_cpu read on a real process)."""
from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "tools"))
from fleet_scenarios import SCENARIOS, ScenarioError, check_poses, cpu_by_part, scenario
from procs import node_label, tree_cpu


@pytest.mark.parametrize("site, name", [(s, n) for s in SCENARIOS for n in SCENARIOS[s]])
def test_every_shipped_start_and_goal_is_clear_on_its_map(site: str, name: str) -> None:
    legs = scenario(site, name)
    check_poses(site, legs)
    assert 2 <= len(legs) <= 3
    starts = [s for s, _ in legs]
    assert all(((a[0] - b[0]) ** 2 + (a[1] - b[1]) ** 2) ** 0.5 >= 0.45
               for i, a in enumerate(starts) for b in starts[i + 1:])    # the fleet file's minimum spacing


def test_a_pose_in_a_wall_or_off_the_map_is_refused_naming_it() -> None:
    legs = [((1.4, -1.5, 0.0), (-3.45, 0.0, 0.0)), ((4.3, -1.5, 0.0), (500.0, 0.0, 0.0))]
    with pytest.raises(ScenarioError, match=r"chefbot1 goal \(-3.45, 0.0\), chefbot2 goal \(500.0, 0.0\)"):
        check_poses("hotel", legs)


def test_an_unknown_scenario_names_the_ones_there_are() -> None:
    with pytest.raises(ScenarioError, match="hotel/head_on"):
        scenario("hotel", "tango")


def test_a_node_is_named_by_its_log_file() -> None:
    argv = ["/usr/bin/python3", "/ws/nodes/amcl", "__name:=amcl", "__log:=/h/.ros/log/1-2/chefbot1-amcl-5.log"]
    assert node_label(argv, "python3") == "chefbot1-amcl-5"
    assert node_label(["/usr/bin/python3", "/usr/bin/rosmaster", "--core"], "rosmaster") == "rosmaster"


def test_cpu_is_split_by_robot_stack_simulator_and_rest() -> None:
    before = {10: ("chefbot1-amcl-3", 5.0), 11: ("chefbot10-amcl-4", 1.0), 12: ("chefbot_sim-2", 20.0),
              13: ("rosmaster", 2.0), 14: ("chefbot1-move_base-7", 3.0), 99: ("reused", 50.0)}
    after = {10: ("chefbot1-amcl-3", 6.5), 11: ("chefbot10-amcl-4", 1.25), 12: ("chefbot_sim-2", 22.0),
             13: ("rosmaster", 2.5), 14: ("chefbot1-move_base-7", 3.5),
             15: ("chefbot2-fleet_member-9", 0.75),        # started in between: counts from 0
             99: ("chefbot2-amcl-1", 0.5)}                 # a reused pid: a new process, counts from 0
    got = cpu_by_part(before, after, ["chefbot1", "chefbot2", "chefbot10"])
    want = {"chefbot1": 2.0, "chefbot2": 1.25, "chefbot10": 0.25, "sim": 2.0, "rest": 0.5}
    assert got.keys() == want.keys()
    assert all(abs(got[k] - v) < 1e-9 for k, v in want.items()), got


def test_tree_cpu_reads_a_busy_child() -> None:
    """A process in a session of its own that spins for 0.5 s of CPU shows about that CPU time."""
    proc = subprocess.Popen([sys.executable, "-c", "import time\nt = time.process_time()\n"
                             "while time.process_time() - t < 0.5: pass\ntime.sleep(30)"],
                            start_new_session=True)
    try:
        deadline = time.monotonic() + 20.0
        spent = 0.0
        while time.monotonic() < deadline:
            spent = sum(secs for _, secs in tree_cpu(proc.pid).values())
            if spent >= 0.45:      # /proc counts whole 10 ms ticks: up to a few short of the 0.5 s spun
                break
            time.sleep(0.05)
        assert 0.45 <= spent < 5.0, spent   # the interpreter's start adds a little
        assert list(tree_cpu(proc.pid)) == [proc.pid]
    finally:
        proc.kill()
        proc.wait()
