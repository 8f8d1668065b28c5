"""Several robots in one pybullet world (chefbot_sim.fleet): they see, touch and push each other,
never see themselves, and otherwise run as independent robots on one clock."""
import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_sim.fleet import Fleet, RobotSpec
from chefbot_sim.sim import SimConfigError, SimOptions
from chefbot_sim.world import parse_object, parse_yaml_world

EMPTY = parse_yaml_world("objects: []")
GAP = 1.5   # m between the two robots' centres, facing each other


@pytest.fixture(scope="module")
def urdf_360() -> str:
    from chefbot_description.model import expand_xacro
    return expand_xacro(args={"lidar": "360"})


def opts(seed: int) -> SimOptions:
    return SimOptions(seed=seed, lidar_fov=360.0, lidar_noise=0.0)


@pytest.fixture()
def pair(urdf_360):
    f = Fleet(EMPTY, [RobotSpec("chefbot1", urdf_360, Pose2D(0.0, 0.0, 0.0), opts(1)),
                      RobotSpec("chefbot2", urdf_360, Pose2D(GAP, 0.0, math.pi), opts(2))])
    f.step(120)   # settle on the wheels
    yield f
    f.close()


def front_and_back(sim) -> tuple[float, float]:
    r, ang = sim.lidar_scan()["ranges"], sim.lidar.angles()
    return r[int(np.argmin(np.abs(ang)))], r[int(np.argmin(np.abs(np.abs(ang) - math.pi)))]


def test_each_robot_sees_the_other_and_never_itself(pair) -> None:
    for sim in pair.sims:
        front, back = front_and_back(sim)
        # at the scan plane (0.42 m) the other's body is its own lidar head on its top plate
        assert GAP - 0.1 < front < GAP - 0.01
        assert back == np.inf                                   # empty world behind, own body unseen
        depth = sim.depth_image()
        cam_x = sim.body.frame_pose(sim.params.depth_camera.depth_frame)[0]
        centre = depth[depth.shape[0] // 2, depth.shape[1] // 2 - 5:depth.shape[1] // 2 + 5]
        other = pair.sims[1 - pair.sims.index(sim)].ground_truth()
        expected = math.hypot(other["x"] - cam_x[0], other["y"] - cam_x[1])
        assert np.nanmin(centre) == pytest.approx(expected - 0.2, abs=0.1)   # camera: the other's body
        assert sim._sonar()["range"] == pytest.approx(expected - 0.2, abs=0.15)


def test_a_robot_out_of_reach_is_not_cast_against(pair) -> None:
    """The ray-cast sensors only ask pybullet about robots within their reach; far away, the
    other robot vanishes from the readings (and costs nothing)."""
    a, b = pair.sims
    b.teleport(Pose2D(30.0, 0.0, math.pi))
    pair.step(24)
    depth = a.depth_image()
    assert np.all(np.isnan(depth[depth.shape[0] // 2]))   # the centre row (lower rows see the floor)
    assert a._sonar()["range"] == math.inf
    assert front_and_back(a)[0] == np.inf      # the lidar's 12 m do not reach either


def test_a_robot_driving_into_another_is_a_bumper_contact_for_both(pair) -> None:
    a, b = pair.sims
    b_start = b.ground_truth()["x"]
    for s in pair.sims:
        s.set_enabled("bumper", True)
    pressed = {0: set(), 1: set()}
    for _ in range(80):                        # 0.3 m/s for up to 8 s: 1.1 m to the contact
        a.set_cmd_vel(0.3, 0.0)
        for i, ev in pair.step(24):
            if ev.kind == "bumper" and ev.data["pressed"]:
                pressed[i].update(ev.data["bodies"])
        if pressed[0] and pressed[1]:
            break
    assert pressed == {0: {"chefbot2"}, 1: {"chefbot1"}}
    for _ in range(10):                        # a body pushes a body
        a.set_cmd_vel(0.3, 0.0)
        pair.step(24)
    assert b.ground_truth()["x"] > b_start + 0.02


def test_robots_drive_independently_on_one_clock(pair) -> None:
    a, b = pair.sims
    b0 = b.ground_truth()
    t0 = pair.time
    clocks = []
    for _ in range(20):                        # 2 s: a turns on the spot, b must not move
        a.set_cmd_vel(0.0, 1.0)
        clocks += [i for i, ev in pair.step(24) if ev.kind == "clock"]
    assert pair.time == pytest.approx(t0 + 2.0, abs=1e-6)
    assert a.time == pytest.approx(pair.time) and b.time == pytest.approx(pair.time)
    assert set(clocks) == {0}                  # one /clock: the first robot's
    assert a.s.odom[2] == pytest.approx(1.9, abs=0.25)
    b1 = b.ground_truth()
    assert math.hypot(b1["x"] - b0["x"], b1["y"] - b0["y"]) < 0.002
    assert abs(b.s.odom[2]) < 0.002


def test_an_obstacle_spawned_is_seen_by_every_robot(pair) -> None:
    a, b = pair.sims
    b.teleport(Pose2D(1.0, 2.0, -math.pi / 2))   # b looks down at where the crate goes
    pair.step(24)
    pair.spawn(parse_object({"name": "crate", "shape": "box", "size": [0.3, 0.3, 1.0], "pose": [1.0, 0.0, 0]},
                            "test"))
    pair.step(24)
    assert front_and_back(a)[0] == pytest.approx(0.85, abs=0.02)
    assert front_and_back(b)[0] == pytest.approx(1.85, abs=0.02)
    pair.reset()
    assert a.spawned == [] and b.spawned == []
    assert b.ground_truth()["x"] == pytest.approx(GAP, abs=0.01)


def test_overlapping_start_poses_are_refused_naming_the_pair(urdf_360) -> None:
    with pytest.raises(SimConfigError, match="'r1' and 'r2' start 0.20 m apart"):
        Fleet(EMPTY, [RobotSpec("r1", urdf_360, Pose2D(0, 0, 0), opts(1)),
                      RobotSpec("r2", urdf_360, Pose2D(0.2, 0, 0), opts(2))])


@pytest.mark.parametrize("names, match", [(["r1", "r1"], "unique"), (["r1", ""], "unique")])
def test_bad_names_are_refused(urdf_360, names, match) -> None:
    with pytest.raises(SimConfigError, match=match):
        Fleet(EMPTY, [RobotSpec(n, urdf_360, Pose2D(2.0 * i, 0, 0), opts(i)) for i, n in enumerate(names)])


def test_a_single_robot_world_steps_only_through_its_fleet(urdf_360) -> None:
    f = Fleet(EMPTY, [RobotSpec("solo", urdf_360, Pose2D(0, 0, 0), opts(1))])
    try:
        with pytest.raises(RuntimeError, match="shared world"):
            f.sims[0].step()
        with pytest.raises(RuntimeError, match="shared world"):
            f.sims[0].snapshot()
        with pytest.raises(KeyError, match="solo"):
            f.robot("chefbot9")
        assert f.robot("solo") is f.sims[0]
    finally:
        f.close()


def test_a_plugin_robot_draws_its_battery_and_charges_standing_on_its_charger(urdf_360) -> None:
    o = SimOptions(seed=1, lidar_fov=0.0, battery_capacity_ah=0.05, battery_initial_soc=0.5, charge_current=5.0)
    f = Fleet(EMPTY, [RobotSpec("chefbot1", urdf_360, Pose2D(0.0, 0.0, 0.0), o, charger=Pose2D(0.0, 0.0, 0.0)),
                      RobotSpec("chefbot2", urdf_360, Pose2D(2.0, 0.0, 0.0), o)])
    try:
        one, two = f.sims
        events = [e for i, e in f.run(10.0) if e.kind == "battery" and i == 0]
        assert len(events) == 10 and events[-1].data["soc"] == pytest.approx(one.battery[0])   # 1 Hz
        # chefbot1 stands on its charger: +5 A - 2.5 A idle into 0.05 Ah for 10 s
        assert one.battery[0] == pytest.approx(0.5 + 2.5 * 10.0 / (0.05 * 3600.0), abs=0.01)
        assert all(e.data["charging"] for e in events)
        # chefbot2 has no charger: it draws 2.5 A idle
        assert two.battery[0] == pytest.approx(0.5 - 2.5 * 10.0 / (0.05 * 3600.0), abs=0.01)
        # driving draws more; driving off the charger stops the charging
        before = [s.battery[0] for s in f.sims]
        for s in f.sims:
            s.set_cmd_vel(0.3, 0.0)
        for _ in range(10):
            for s in f.sims:
                s.set_cmd_vel(0.3, 0.0)
            f.run(0.5)
        assert one.battery[0] < before[0] and two.battery[0] < before[1]
        drop = before[1] - two.battery[0]
        assert drop > 2.5 * 5.0 / (0.05 * 3600.0) + 1e-4        # more than idle alone
        assert one.battery[1] > 0                                 # off its charger: drawing, not charging
    finally:
        f.close()
