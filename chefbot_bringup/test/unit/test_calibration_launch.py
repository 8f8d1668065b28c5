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


# ---------------------------------------------------------------- who reads which ticks_meter (issue 31)
def node_getter(params: dict[str, object], node: str):
    """``rospy.get_param`` as the node ``node`` (a full name: /ns/name) sees the launch's parameter
    server: ``~x`` is ``<node>/x``, a relative ``x`` is ``x`` in the node's namespace."""
    ns = node.rsplit("/", 1)[0] + "/"

    def get(name: str, default: object) -> object:
        full = name if name.startswith("/") else f"{node}/{name[1:]}" if name.startswith("~") else ns + name
        return params.get(full, default)
    return get


def launch_nodes(launch: Path, *args: str) -> tuple[dict[str, object], dict[str, str]]:
    """The parameter server and the full name -> type of each node the launch would start."""
    config = roslaunch.config.load_config_default([(str(launch), list(args))], None)
    nodes = {(n.namespace + n.name).replace("//", "/"): n.type for n in config.nodes}
    return {name: p.value for name, p in config.params.items()}, nodes


@pytest.fixture(scope="module")
def node_modules():
    """diff_tf and pid_velocity of this package, imported (nothing starts): their own PARAMS and read_params."""
    import gen_node_docs  # tools/: imports a node script as a module

    include = Path(resolve_args("$(find chefbot_bringup)/launch/includes/diff_drive.launch.xml")).resolve()
    assert include == PKG / "launch" / "includes" / "diff_drive.launch.xml", (
        f"the launch would include {include}, another checkout's: put this one first on ROS_PACKAGE_PATH "
        "(and keep its devel space off CMAKE_PREFIX_PATH, which $(find pkg)/path searches first)")
    return {n: gen_node_docs.load_node(PKG / "nodes" / n) for n in ("diff_tf", "pid_velocity")}


def drive_ticks(node_modules, params: dict[str, object], nodes: dict[str, str], ns: str = "") -> dict[str, object]:
    """What each drive node would use: diff_tf's (left, right) ticks/m, each PID's ticks_meter and side,
    each read by the node's own read_params (through its PARAMS) from the launch's parameter server."""
    assert nodes[f"{ns}/diff_tf"] == "diff_tf"
    assert nodes[f"{ns}/lwheel_pid"] == nodes[f"{ns}/rwheel_pid"] == "pid_velocity"
    odom, _ = node_modules["diff_tf"].read_params(node_getter(params, f"{ns}/diff_tf"))
    out: dict[str, object] = {"diff_tf": odom.wheel_ticks_meter, "base_width": odom.base_width}
    for pid in ("lwheel_pid", "rwheel_pid"):
        wheel, cfg = node_modules["pid_velocity"].read_params(node_getter(params, f"{ns}/{pid}"))
        out[pid] = (wheel.side, cfg.ticks_meter)
    return out


def written_calibration(tmp_path: Path, left: float = 29950.0, right: float = 29610.0):
    """A calibration YAML as odometry_calibration writes it (wheels 0.8 % / -0.3 % off, base 0.312 m)."""
    from chefbot_bringup.odometry_calibration import Calibration

    cal = Calibration(ticks_meter_left=left, ticks_meter_right=right, base_width=0.312,
                      ticks_meter_before=29708.0, base_width_before=0.30)
    return cal, cal.save(tmp_path / "calibration.yaml")


def test_without_per_wheel_values_every_drive_node_uses_ticks_meter(node_modules, shipped) -> None:
    params, nodes = launch_nodes(LAUNCH)
    assert "/ticks_meter_left" not in params and "/ticks_meter_right" not in params
    tm = float(shipped["/ticks_meter"])
    assert drive_ticks(node_modules, params, nodes) == {
        "diff_tf": (tm, tm), "base_width": shipped["/base_width"],
        "lwheel_pid": ("left", tm), "rwheel_pid": ("right", tm)}


def test_a_calibration_yaml_gives_each_node_its_wheels_ticks_meter(node_modules, tmp_path: Path) -> None:
    """The YAML odometry_calibration writes (top-level ticks_meter, base_width, ticks_meter_left,
    ticks_meter_right), loaded by ``calibration:=`` after diff_drive.yaml: diff_tf divides each wheel's
    ticks by its own value, and each PID uses its wheel's."""
    cal, path = written_calibration(tmp_path)
    params, nodes = launch_nodes(LAUNCH, f"calibration:={path}")
    assert params["/ticks_meter"] == pytest.approx(cal.ticks_meter, abs=0.05)   # for the one-value readers
    assert drive_ticks(node_modules, params, nodes) == {
        "diff_tf": (29950.0, 29610.0), "base_width": 0.312,
        "lwheel_pid": ("left", 29950.0), "rwheel_pid": ("right", 29610.0)}


def test_per_wheel_values_in_a_namespace(node_modules, tmp_path: Path) -> None:
    _, path = written_calibration(tmp_path)
    outer = tmp_path / "ns.launch"
    outer.write_text(f"""<launch>
  <group ns="chefbot1">
    <include file="{LAUNCH}"><arg name="calibration" value="{path}"/></include>
  </group>
  <param name="ticks_meter_left" value="1.0"/>   <!-- another robot's: not chefbot1's -->
</launch>
""")
    params, nodes = launch_nodes(outer)
    assert drive_ticks(node_modules, params, nodes, ns="/chefbot1") == {
        "diff_tf": (29950.0, 29610.0), "base_width": 0.312,
        "lwheel_pid": ("left", 29950.0), "rwheel_pid": ("right", 29610.0)}


def test_one_wheel_given_the_other_keeps_ticks_meter_and_diff_tf_private_wins(node_modules, tmp_path) -> None:
    cal = tmp_path / "right_only.yaml"
    cal.write_text("ticks_meter_right: 29500\ndiff_tf: {ticks_meter_left: 29800}\n")
    params, nodes = launch_nodes(LAUNCH, f"calibration:={cal}")
    assert drive_ticks(node_modules, params, nodes) == {
        "diff_tf": (29800.0, 29500.0), "base_width": 0.30,
        "lwheel_pid": ("left", 29708.0), "rwheel_pid": ("right", 29500.0)}


def test_a_bad_per_wheel_value_is_refused_by_name(node_modules, tmp_path: Path) -> None:
    from chefbot_common.params import ParamError

    cal = tmp_path / "bad.yaml"
    cal.write_text("ticks_meter_left: -29950\n")
    params, _ = launch_nodes(LAUNCH, f"calibration:={cal}")
    for node, module in (("/diff_tf", "diff_tf"), ("/lwheel_pid", "pid_velocity"), ("/rwheel_pid", "pid_velocity")):
        with pytest.raises(ParamError, match=r"parameter ticks_meter_left must be a positive"):
            node_modules[module].read_params(node_getter(params, node))
