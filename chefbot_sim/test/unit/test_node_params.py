"""chefbot_sim_node's parameters, request queue and message builders (no master)."""
from __future__ import annotations

import math
import threading

import numpy as np
import pytest

from chefbot_common.params import ParamError
from chefbot_sim.node_params import (
    FIRMWARE_MAX_LAG,
    STEPS_PER_BATCH,
    fleet_members,
    missing_models,
    pacing,
    read_sim_params,
)
from chefbot_sim.requests import SimRequests


def getter(d: dict):
    return lambda name, default: d.get(name, default)


BASE = {"robot_description": "<robot name='r'/>", "~world": "/tmp/w.yaml"}


def test_defaults_and_sim_options() -> None:
    node, opts = read_sim_params(getter({**BASE, "~x": 1, "~yaw": 0.5, "~seed": 3, "~drive": "firmware"}))
    assert (node.x, node.y, node.yaw, node.real_time_factor) == (1.0, 0.0, 0.5, 1.0)
    assert opts.seed == 3 and opts.drive == "firmware"
    assert "robot name" not in repr(node)


@pytest.mark.parametrize("params,match", [
    ({"~world": "/tmp/w.yaml"}, "robot_description"),
    ({"robot_description": "<robot/>"}, "world"),
    ({**BASE, "~x": math.nan}, "~x"),
    ({**BASE, "~real_time_factor": -1.0}, "~real_time_factor"),
    ({**BASE, "~gui": "yes"}, "~gui"),
    ({**BASE, "~drive": "teleport"}, "drive"),
    ({**BASE, "~seed": 1.5}, "~seed"),
    ({**BASE, "~model_timeout": -1.0}, "~model_timeout"),
])
def test_bad_params_are_named(params: dict, match: str) -> None:
    with pytest.raises(ValueError, match=match):
        read_sim_params(getter(params))


def test_param_error_type() -> None:
    with pytest.raises(ParamError):
        read_sim_params(getter({**BASE, "~firmware_max_rtf": -2.0}))


def test_firmware_cap_is_off_by_default_and_still_works_and_paces_every_step() -> None:
    node, _ = read_sim_params(getter({**BASE, "~real_time_factor": 0.0}))
    assert node.effective_rtf(firmware=True) == 0.0          # uncapped by default
    node, _ = read_sim_params(getter({**BASE, "~real_time_factor": 3.0, "~firmware_max_rtf": 1.0}))
    assert node.effective_rtf(firmware=False) == 3.0
    assert node.effective_rtf(firmware=True) == 1.0
    assert pacing(False, 1.0) == (STEPS_PER_BATCH, None)
    assert pacing(True, 1.0) == (1, FIRMWARE_MAX_LAG)


def test_requests_run_in_order_and_errors_are_logged() -> None:
    reqs, out, logs = SimRequests(), [], []
    reqs.put(lambda: out.append(1))
    reqs.put_guarded(lambda: (_ for _ in ()).throw(ValueError("no such body")), "remove", (ValueError,), logs.append)
    reqs.put(lambda: out.append(2))
    reqs.run_pending()
    assert out == [1, 2] and logs == ["chefbot_sim: remove rejected: no such body"]


def test_call_waits_for_the_loop_and_gives_up_on_stop() -> None:
    reqs, ran = SimRequests(), []
    loop = threading.Thread(target=lambda: [reqs.run_pending() or threading.Event().wait(0.01) for _ in range(500)
                                            if not ran])
    loop.start()
    reqs.call(lambda: ran.append(True), stop=lambda: False, poll=0.01)
    loop.join()
    assert ran == [True]
    reqs.call(lambda: None, stop=lambda: True, poll=0.01)   # nobody runs it: returns on stop


def test_message_builders() -> None:
    rospy_time = pytest.importorskip("genpy").Time
    from chefbot_sim import ros_io
    t = rospy_time.from_sec(2.5)
    odom, tf = ros_io.odom_msgs({"x": 1.0, "y": 2.0, "yaw": math.pi / 2, "v": 0.3, "w": 0.1}, t, "odom", "base")
    assert (odom.header.frame_id, odom.child_frame_id, odom.pose.pose.position.x) == ("odom", "base", 1.0)
    assert odom.pose.pose.orientation.z == pytest.approx(math.sqrt(0.5))
    assert tf.transform.translation.y == 2.0 and odom.twist.twist.angular.z == 0.1
    img = ros_io.rgb_to_image(np.zeros((2, 3, 3), np.uint8), t, "cam")
    assert (img.height, img.width, img.step, img.encoding, len(img.data)) == (2, 3, 9, "rgb8", 18)
    depth = ros_io.depth_to_image(np.ones((2, 3), np.float32), t, "cam")
    assert (depth.encoding, depth.step) == ("32FC1", 12)
    imu = ros_io.imu_msg({"orientation": np.array([0, 0, 0, 1.0]), "angular_velocity": np.zeros(3),
                          "linear_acceleration": np.array([0, 0, 9.81]), "gyro_variance": 0.01,
                          "accel_variance": 0.02}, t, "imu")
    assert imu.angular_velocity_covariance[4] == 0.01 and imu.linear_acceleration.z == 9.81


def test_sim_stamp_rounds_to_the_nanosecond() -> None:
    """Sim time is a float sum of physics steps: stamps must not lose a nanosecond to truncation
    (a tf future-dated by 0.3 s from one scan must meet the scan 0.3 s later exactly)."""
    import rospy

    from chefbot_sim.ros_io import sim_stamp
    t = sum([1.0 / 240.0] * 240 * 125) + 0.3          # ~125.3 with float error
    assert rospy.Time.from_sec(125.3).nsecs == 299999999   # what rospy would give
    assert sim_stamp(t) == rospy.Time(125, 300000000)
    assert sim_stamp(124.9) + rospy.Duration(0.3) == sim_stamp(125.2)
    assert sim_stamp(0.0) == rospy.Time(0)


FLEET = "chefbot_navigation/maps/hotel_fleet.yaml"


def test_a_fleet_world_names_the_robots_whose_models_are_missing(pkg) -> None:
    """The world may start before the robots' stacks (each on its own PC): the node waits for the
    models it lacks, then names them."""
    fleet = {"~world": "/tmp/w.yaml", "~fleet_file": str(pkg.parent / FLEET), "~robots": 2}
    node, _ = read_sim_params(getter(fleet))
    assert node.model_timeout > 0
    assert missing_models(node, getter({})) == ["chefbot1", "chefbot2"]
    models = {"chefbot2/robot_description": "<robot name='c2'/>"}
    assert missing_models(node, getter(models)) == ["chefbot1"]
    with pytest.raises(ParamError, match="chefbot1/robot_description is not set.*fleet_robot.launch robot:=chefbot1"):
        fleet_members(node, getter(models))
    models["chefbot1/robot_description"] = "<robot name='c1'/>"
    assert missing_models(node, getter(models)) == []
    assert [m.name for m in fleet_members(node, getter(models))] == ["chefbot1", "chefbot2"]


def test_robot_options_give_one_robot_of_a_fleet_its_own_settings() -> None:
    from chefbot_sim.node_params import check_robot_options, member_options
    from chefbot_sim.sim import SimOptions

    opts = SimOptions(seed=4, battery_initial_soc=0.4)
    per = check_robot_options({"chefbot2": {"battery_initial_soc": 0.7, "drive": "firmware"}},
                              ["chefbot1", "chefbot2"])
    one, two = member_options(opts, 0, "chefbot1", per.get("chefbot1")), member_options(opts, 1, "chefbot2",
                                                                                          per.get("chefbot2"))
    assert one.battery_initial_soc == pytest.approx(0.4) and one.drive == opts.drive and one.seed == 4
    assert two.battery_initial_soc == pytest.approx(0.7) and two.drive == "firmware"
    assert two.seed == 5 and two.lidar_frame == "chefbot2/laser"      # what every member gets still holds
    assert member_options(opts, 1, "chefbot2", {"seed": 9}).seed == 9
    assert check_robot_options(None, ["chefbot1"]) == {}


@pytest.mark.parametrize("mapping, over, match", [
    ({"chefbot9": {"battery_initial_soc": 0.5}}, None, "names chefbot9, but the sim holds chefbot1"),
    (["chefbot1"], None, "must be a map robot name"),
    ({"chefbot1": 0.5}, None, "robot_options/chefbot1 must be a map option"),
    (None, {"no_such_option": 1}, "robot_options/chefbot1/no_such_option: not a per-robot"),
    (None, {"time_step": 0.01}, "world steps every robot alike"),
    (None, {"battery_initial_soc": "full"}, "robot_options/chefbot1/battery_initial_soc must be a number"),
    (None, {"battery_initial_soc": 1.5}, "robot_options/chefbot1.*battery_initial_soc must be within 0..1"),
])
def test_bad_robot_options_are_named(mapping, over, match) -> None:
    from chefbot_sim.node_params import check_robot_options, member_options
    from chefbot_sim.sim import SimOptions

    with pytest.raises(ParamError, match=match):
        if mapping is not None:
            check_robot_options(mapping, ["chefbot1"])
        member_options(SimOptions(), 0, "chefbot1", over)
