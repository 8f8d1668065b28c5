"""robot_standalone.launch's ``calibration`` arg: a calibration YAML loaded after diff_drive.yaml.

The launch file is loaded with roslaunch's own loader (``roslaunch.config.load_config_default``,
as ``roslaunch --dump-params`` does): no master, no node started.  The parameter server the launch
would set up is compared with the two YAML files.
"""
from __future__ import annotations

import os
import sys
from pathlib import Path

import pytest
import yaml

roslaunch = pytest.importorskip("roslaunch", reason="ROS 1 roslaunch not importable: run through tools/with_env.sh")
from roslaunch.core import RLException  # noqa: E402
from roslaunch.substitution_args import resolve_args  # noqa: E402

PKG = Path(__file__).resolve().parents[2]
LAUNCH = PKG / "launch" / "robot_standalone.launch"
sys.path.insert(0, str(PKG.parent / "tools"))
import procs  # noqa: E402  (the workspace's process-group helpers)

HANG_GUARD_S = 60.0   # against hangs only

CALIBRATION = """\
# written by a calibration run
ticks_meter: 29950
base_width: 0.312
lwheel_pid: {Kp: 350.0, Ki: 90.0}
rwheel_pid: {Kp: 360.0}
"""


def flatten(tree: dict, prefix: str = "/") -> dict[str, object]:
    """Parameter names (as roslaunch sets them: one per leaf) and values of a YAML mapping."""
    out: dict[str, object] = {}
    for key, value in tree.items():
        name = prefix + str(key)
        if isinstance(value, dict):
            out.update(flatten(value, name + "/"))
        else:
            out[name] = value
    return out


def launch_params(*args: str, launch: Path = LAUNCH) -> dict[str, object]:
    """What the launch would put on the parameter server, with ``name:=value`` args."""
    config = roslaunch.config.load_config_default([(str(launch), list(args))], None)
    return {name: p.value for name, p in config.params.items()}


@pytest.fixture(scope="module")
def shipped() -> dict[str, object]:
    """diff_drive.yaml as the launch file's default ``diff_drive_params`` finds it (``$(find)``)."""
    path = resolve_args("$(find chefbot_bringup)/param/diff_drive.yaml")
    return flatten(yaml.safe_load(Path(path).read_text()))


@pytest.fixture()
def calibration(tmp_path: Path) -> Path:
    path = tmp_path / "calibration.yaml"
    path.write_text(CALIBRATION)
    return path


# the drive params the launch file itself overrides after the include (not the YAML's business)
LAUNCH_SET = {"/diff_tf/use_imu", "/diff_tf/odom_frame_id", "/diff_tf/base_frame_id",
              "/twist_to_motors/event_driven", "/lwheel_pid/event_driven", "/rwheel_pid/event_driven",
              "/diff_tf/event_driven"}


def test_without_calibration_the_drive_params_are_diff_drive_yaml(shipped) -> None:
    for params in (launch_params(), launch_params("calibration:=")):
        assert {k: params[k] for k in shipped if k not in LAUNCH_SET} == \
            {k: v for k, v in shipped.items() if k not in LAUNCH_SET}


def test_calibration_overrides_its_keys_and_keeps_the_others(shipped, calibration: Path) -> None:
    params = launch_params(f"calibration:={calibration}")
    ours = flatten(yaml.safe_load(CALIBRATION))
    assert ours == {"/ticks_meter": 29950, "/base_width": 0.312, "/lwheel_pid/Kp": 350.0,
                    "/lwheel_pid/Ki": 90.0, "/rwheel_pid/Kp": 360.0}
    for name, value in ours.items():
        assert params[name] == value != shipped[name], name
    # everything the calibration does not name stays as diff_drive.yaml has it, leaf by leaf
    # (rwheel_pid/Ki next to a calibrated rwheel_pid/Kp)
    for name in ("/max_wheel_speed", "/encoder_min", "/rwheel_pid/Ki", "/lwheel_pid/Kd", "/lwheel_pid/out_max",
                 "/twist_to_motors/rate", "/diff_tf/twist_window"):
        assert params[name] == shipped[name], name
    assert {k: params[k] for k in shipped if k not in ours and k not in LAUNCH_SET} == \
        {k: v for k, v in shipped.items() if k not in ours and k not in LAUNCH_SET}
    # the launch file's own overrides after the include still hold
    assert params["/diff_tf/use_imu"] is False and params["/lwheel_pid/event_driven"] is True


def test_calibration_lands_in_the_namespace_of_the_drive_params(tmp_path: Path, calibration: Path) -> None:
    outer = tmp_path / "ns.launch"
    outer.write_text(f"""<launch>
  <group ns="chefbot1">
    <include file="{LAUNCH}"><arg name="calibration" value="{calibration}"/></include>
  </group>
</launch>
""")
    params = launch_params(launch=outer)
    assert params["/chefbot1/ticks_meter"] == 29950 and params["/chefbot1/lwheel_pid/Kp"] == 350.0
    assert params["/chefbot1/rwheel_pid/Ki"] == 100.0
    assert "/ticks_meter" not in params


def test_missing_calibration_file_is_roslaunch_error(tmp_path: Path) -> None:
    missing = tmp_path / "no_such_calibration.yaml"
    with pytest.raises(RLException, match=rf"file does not exist \[{missing}\]"):
        launch_params(f"calibration:={missing}")


def test_roslaunch_ends_on_a_missing_calibration_file_before_starting_anything(tmp_path: Path) -> None:
    """The command a user runs: exit 1 and roslaunch's message, no master started (the file is read
    before anything runs).  (``roslaunch --dump-params`` prints the same message but exits 0.)"""
    missing = tmp_path / "no_such_calibration.yaml"
    port = procs.free_port()
    env = dict(os.environ, ROS_MASTER_URI=f"http://127.0.0.1:{port}", ROS_HOME=str(tmp_path / "ros_home"))
    r = procs.run_captured(["roslaunch", "-p", str(port), str(LAUNCH), f"calibration:={missing}"],
                           timeout=HANG_GUARD_S, env=env)
    out = r.stdout + r.stderr
    assert r.returncode == 1, out
    assert f"file does not exist [{missing}]" in out, out
    assert "started roslaunch server" not in out and "ROS_MASTER_URI=" not in out, out
