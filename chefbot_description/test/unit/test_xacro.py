"""xacro expansion, check_urdf, and clear failures for bad arguments or files."""
from __future__ import annotations

import os
import signal
import socket
import subprocess
from pathlib import Path

import pytest
import yaml

from chefbot_description import model

MODEL = model.default_model_path()
TIMEOUT_S = 60.0


def run(cmd: list[str], **kw) -> subprocess.CompletedProcess:
    return subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT_S, check=False, **kw)


def xacro(*args: str) -> subprocess.CompletedProcess:
    return run(["xacro", str(MODEL), *args])


@pytest.mark.parametrize("args", [(), ("camera:=astra",), ("depth_width:=320", "depth_height:=240"),
                                  ("sim_params:=false",)])
def test_xacro_expands_without_warnings(args: tuple[str, ...]) -> None:
    proc = xacro(*args)
    assert proc.returncode == 0, proc.stderr
    assert proc.stderr == ""
    assert "<robot" in proc.stdout


@pytest.mark.parametrize("args", [(), ("camera:=astra",), ("sim_params:=false",)])
def test_check_urdf_accepts_model(args: tuple[str, ...], tmp_path: Path) -> None:
    urdf = tmp_path / "chefbot.urdf"
    urdf.write_text(model.expand_xacro(args=dict(a.split(":=") for a in args)))
    proc = run(["check_urdf", str(urdf)])
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "Successfully Parsed XML" in proc.stdout
    assert "root Link: base_footprint" in proc.stdout


def test_check_urdf_accepts_physics_variant(urdf_xml: str, tmp_path: Path) -> None:
    urdf = tmp_path / "physics.urdf"
    urdf.write_text(model.urdf_for_physics(urdf_xml))
    proc = run(["check_urdf", str(urdf)])
    assert proc.returncode == 0, proc.stdout + proc.stderr


@pytest.mark.parametrize("arg, needle", [
    ("camera:=lidar", "invalid_camera_arg__use_kinect_or_astra"),
    ("depth_width:=abc", "depth_width"),
    ("depth_height:=-", "depth_height"),
    ("sim_params:=maybe", "maybe"),
])
def test_bad_xacro_argument_fails_naming_it(arg: str, needle: str) -> None:
    proc = xacro(arg)
    assert proc.returncode != 0
    assert needle in proc.stderr


def test_missing_file_fails_naming_it(tmp_path: Path) -> None:
    missing = tmp_path / "no_such_model.xacro"
    proc = run(["xacro", str(missing)])
    assert proc.returncode != 0
    assert str(missing) in proc.stderr
    with pytest.raises(model.XacroError, match="no_such_model.xacro"):
        model.expand_xacro(missing)


def test_expand_xacro_reports_bad_argument() -> None:
    with pytest.raises(model.XacroError, match="depth_width"):
        model.expand_xacro(args={"depth_width": "wide"})


def test_depth_size_arguments_reach_sim_block() -> None:
    params = model.load_sim_params(model.expand_xacro(args={"depth_width": "320", "depth_height": "240"}))
    assert (params.depth_camera.width, params.depth_camera.height) == (320, 240)


# ----------------------------------------------------------------- launch files
def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


def roslaunch(args: list[str], tmp_path: Path) -> tuple[int, str]:
    """Run roslaunch in its own process group; kill the whole group if it outlives the timeout."""
    env = dict(os.environ, ROS_LOG_DIR=str(tmp_path / "log"), ROS_HOME=str(tmp_path / "home"))
    env.pop("ROS_MASTER_URI", None)
    proc = subprocess.Popen(["roslaunch", *args], stdout=subprocess.PIPE, stderr=subprocess.STDOUT,
                            stdin=subprocess.DEVNULL, text=True, env=env, start_new_session=True)
    try:
        out, _ = proc.communicate(timeout=TIMEOUT_S)
    except subprocess.TimeoutExpired:
        os.killpg(proc.pid, signal.SIGINT)
        try:
            out, _ = proc.communicate(timeout=15)
        except subprocess.TimeoutExpired:
            os.killpg(proc.pid, signal.SIGKILL)
            out, _ = proc.communicate()
        pytest.fail(f"roslaunch {' '.join(args)} did not exit within {TIMEOUT_S} s:\n{out}")
    return proc.returncode, out


def test_upload_model_with_missing_file_fails_clearly(tmp_path: Path) -> None:
    missing = tmp_path / "missing.xacro"
    rc, out = roslaunch(["-p", str(free_port()), "chefbot_description", "upload_model.launch",
                         f"model:={missing}"], tmp_path)
    assert rc != 0, out
    assert "Cannot load command parameter [robot_description]" in out
    assert str(missing) in out


def test_upload_model_loads_description(tmp_path: Path) -> None:
    rc, out = roslaunch(["--dump-params", "chefbot_description", "upload_model.launch", "camera:=astra"],
                        tmp_path)
    assert rc == 0, out
    params = yaml.safe_load(out)
    robot = model.parse_urdf(params["/robot_description"])
    size = next(g.size for g in robot.links["camera_link"].collisions if g.kind == "box")
    assert size[1] == pytest.approx(0.165)  # Astra body width
    assert model.load_sim_params(params["/robot_description"]).depth_camera.horizontal_fov == \
        pytest.approx(1.0471975511965976)


@pytest.mark.parametrize("launch, args, nodes", [
    ("view_model.launch", ["rviz:=false"], {"/robot_state_publisher", "/joint_state_publisher"}),
    ("view_model.launch", [], {"/robot_state_publisher", "/joint_state_publisher", "/rviz"}),
    ("view_model.launch", ["rviz:=false", "gui:=true"], {"/robot_state_publisher", "/joint_state_publisher_gui"}),
    ("view_navigation.launch", [], {"/rviz"}),
])
def test_launch_file_nodes(launch: str, args: list[str], nodes: set[str], tmp_path: Path) -> None:
    rc, out = roslaunch(["--nodes", "chefbot_description", launch, *args], tmp_path)
    assert rc == 0, out
    assert set(out.split()) == nodes


def test_frame_prefix_prefixes_every_link_and_sim_frame_not_joints() -> None:
    """xacro frame_prefix (a robot in a namespace): links and the <chefbot_sim> frames carry it;
    joints keep their names; an empty prefix is the default model byte for byte."""
    plain, prefixed = model.expand_xacro(), model.expand_xacro(args={"frame_prefix": "chefbot1/"})
    assert model.expand_xacro(args={"frame_prefix": ""}) == plain
    a, b = model.parse_urdf(plain), model.parse_urdf(prefixed)
    assert set(b.links) == {"chefbot1/" + n for n in a.links}
    assert set(b.joints) == set(a.joints)
    sim = model.load_sim_params(prefixed)
    assert (sim.drive.odom_frame, sim.drive.base_frame) == ("chefbot1/odom", "chefbot1/base_footprint")
    assert sim.depth_camera.link == "chefbot1/camera_link"
    assert {c.parent for c in sim.cliffs} == {"chefbot1/base_link"}
