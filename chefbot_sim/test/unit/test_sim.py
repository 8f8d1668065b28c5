"""The pybullet facade and the sim core in DIRECT mode: determinism, snapshots,
sensor geometry, drive timeout, world edits."""
import math

import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_sim.bullet import BulletError, BulletSim
from chefbot_sim.raycast import RayCaster
from chefbot_sim.sim import CameraModel, Pacer, SimConfigError, SimOptions, Simulator
from chefbot_sim.world import Shape, World, parse_yaml_world

WALL = parse_yaml_world("objects: [{name: wall, shape: box, size: [0.2, 4.0, 1.0], pose: [3.0, 0.0, 0.0]}]")
DEPTH_X = 0.1615   # m, camera_depth_frame ahead of base_footprint in chefbot.xacro
SONAR_X = 0.1425   # m, ultrasonic_link ahead of base_footprint


def drive(sim: Simulator, v: float, w: float, seconds: float) -> list:
    """Command (v, w) every 0.1 s of sim time (inside the 0.6 s timeout)."""
    events = []
    for _ in range(int(round(seconds / 0.1))):
        sim.set_cmd_vel(v, w)
        for _ in range(24):
            events += sim.step()
    return events


@pytest.fixture()
def sim(urdf):
    s = Simulator(urdf, WALL, options=SimOptions(seed=3))
    yield s
    s.close()


def trajectory(urdf, seed: int) -> np.ndarray:
    s = Simulator(urdf, WALL, options=SimOptions(seed=seed))
    try:
        ev = drive(s, 0.2, 0.4, 2.0)
        gt = [e.data["position"] for e in ev if e.kind == "ground_truth"]
        imu = [e.data["angular_velocity"] for e in ev if e.kind == "imu"]
        return np.concatenate([np.ravel(gt), np.ravel(imu)])
    finally:
        s.close()


def test_same_seed_same_run(urdf):
    a, b = trajectory(urdf, 7), trajectory(urdf, 7)
    assert np.array_equal(a, b)
    assert not np.array_equal(a, trajectory(urdf, 8))  # the noise differs


def test_snapshot_restore_continues_identically(sim):
    drive(sim, 0.2, 0.3, 0.5)
    snap = sim.snapshot()
    first = drive(sim, 0.1, -0.5, 1.0)
    sim.restore(snap)
    second = drive(sim, 0.1, -0.5, 1.0)
    assert [e.kind for e in first] == [e.kind for e in second]
    for a, b in zip(first, second, strict=True):
        assert a.stamp == b.stamp
        if a.kind in ("ground_truth", "odom", "imu"):
            for k in a.data:
                assert np.array_equal(np.asarray(a.data[k]), np.asarray(b.data[k])), (a.kind, k)


def test_drive_distance_odometry_and_timeout(sim):
    x0 = sim.ground_truth()["x"]
    drive(sim, 0.2, 0.0, 5.0)
    gt = sim.ground_truth()
    assert gt["x"] - x0 == pytest.approx(1.0, abs=0.05)
    assert sim.s.odom[0] == pytest.approx(gt["x"] - x0, rel=0.02)
    sim.run(0.5)   # within the 0.6 s timeout: still driving
    assert sim.ground_truth()["linear"][0] > 0.15
    sim.run(0.5)   # past it: stopped
    x1 = sim.ground_truth()["x"]
    sim.run(0.5)
    assert abs(sim.ground_truth()["x"] - x1) < 1e-3


def test_depth_geometry_wall_at_known_distance(sim):
    sim.teleport(Pose2D(1.0, 0.0, 0.0))
    sim.run(0.3)
    x = sim.ground_truth()["x"]
    img = sim.depth_image()
    cam = sim.depth_camera
    expected = 2.9 - (x + DEPTH_X)
    band = img[int(cam.cy) - 4:int(cam.cy) + 5]
    # a wall facing the camera has the same depth (optical z) in every column
    assert np.nanmedian(band) == pytest.approx(expected, abs=0.02)
    assert np.all(np.abs(band[np.isfinite(band)] - expected) < 0.03)
    assert img.dtype == np.float32 and img.shape == (cam.height, cam.width)


def test_depth_pixel_directions_follow_camera_info(sim):
    """Turn the robot so the wall's edge falls inside the image; the column where
    the depth steps must be where the pinhole model puts the edge."""
    sim.teleport(Pose2D(0.0, 0.0, 0.0))
    sim.run(0.2)
    sim.spawn(Shape("post", "box", (0.2, 0.2, 1.0), (2.0, 0.5, 0.5)))
    img = sim.depth_image()
    cam = sim.depth_camera
    row = img[int(round(cam.cy))]
    pos, rot = sim.bullet.frame_pose(sim.params.depth_camera.depth_frame)
    # the post's near face (x = 1.9, y in [0.4, 0.6]) projects between these
    # columns; optical x points right, i.e. along -y of the level robot
    z = 1.9 - pos[0]
    u_left = cam.cx + cam.fx * (-(0.6 - pos[1])) / z
    u_right = cam.cx + cam.fx * (-(0.4 - pos[1])) / z
    assert 0 < u_left < u_right < cam.cx
    on_face = np.abs(row - z) < 0.02
    u = np.arange(cam.width)
    assert on_face[(u > u_left + 0.6) & (u < u_right - 0.6)].all()
    assert not on_face[(u < u_left - 0.6) | (u > u_right + 0.6)].any()


def test_ultrasonic_cone_sees_the_wall(sim):
    sim.teleport(Pose2D(1.0, 0.0, 0.0))
    sim.run(0.3)
    r = sim._read("ultrasonic")
    assert r["range"] == pytest.approx(2.9 - (sim.ground_truth()["x"] + SONAR_X), abs=0.02)
    sim.teleport(Pose2D(0.0, 0.0, math.pi))   # facing away: nothing within 4 m
    sim.run(0.3)
    assert sim._read("ultrasonic")["range"] == math.inf


def test_imu_matches_ground_truth_while_turning(sim):
    rest = []
    sim.run(1.0, rest.append)
    acc = [e.data["linear_acceleration"] for e in rest if e.kind == "imu" and e.stamp > 0.5]
    # +g at rest (x, y carry the contact jitter of the rigid casters: a few 0.1 m/s^2)
    assert np.mean(acc, axis=0) == pytest.approx([0.0, 0.0, 9.81], abs=0.3)
    assert np.mean(acc, axis=0)[2] == pytest.approx(9.81, abs=0.1)
    ev = drive(sim, 0.0, 0.8, 2.0)
    imu = np.mean([e.data["angular_velocity"][2] for e in ev if e.kind == "imu" and e.stamp > 1.0])
    gt = np.mean([e.data["angular"][2] for e in ev if e.kind == "ground_truth" and e.stamp > 1.0])
    assert gt > 0.5 and imu == pytest.approx(gt, abs=0.01)


def test_bumper_spawn_remove_reset(sim):
    sim.spawn(Shape("crate", "box", (0.4, 0.4, 0.5), (0.45, 0.0, 0.25)))
    with pytest.raises(ValueError):
        sim.spawn(Shape("crate", "box", (0.4, 0.4, 0.5), (0.45, 0.0, 0.25)))
    drive(sim, 0.2, 0.0, 1.0)
    assert sim._read("bumper") == {"pressed": True, "bodies": ["crate"]}
    assert sim._read("ultrasonic")["range"] < 0.1
    sim.remove("crate")
    assert sim.spawned == []
    sim.spawn(Shape("crate2", "sphere", (0.2,), (1.0, 1.0, 0.2)))
    sim.reset()
    assert sim.spawned == [] and sim.s.odom == (0.0, 0.0, 0.0)
    gt = sim.ground_truth()
    assert abs(gt["x"]) < 1e-3 and abs(gt["y"]) < 1e-3
    assert sim._read("bumper")["pressed"] is False
    with pytest.raises(ValueError):
        sim.remove("nothing")


def test_schedule_rates(sim):
    ev = sim.step(240)
    counts = {k: sum(e.kind == k for e in ev) for k in sim.rates}
    assert counts["clock"] == 100 and counts["imu"] == 50 and counts["depth"] == 10
    assert counts["ultrasonic"] == 10 and counts["odom"] == 50 and counts["rgb"] == round(sim.rates["rgb"]) == 10
    sim.set_enabled("rgb", False)
    assert not any(e.kind == "rgb" for e in sim.step(240))
    rgb = sim.rgb_image()
    assert rgb.shape == (sim.rgb_camera.height, sim.rgb_camera.width, 3) and rgb.dtype == np.uint8


def test_camera_model_and_info():
    cam = CameraModel.from_fov(160, 120, math.radians(58.0))
    assert (cam.cx, cam.cy) == pytest.approx((79.5, 59.5))
    d = cam.rays(np.array([59.5]), np.array([0.0, 159.0]))
    assert d[0, 0] == pytest.approx(-math.tan(math.radians(29.0)) * 159 / 160)
    info = cam.info()
    assert info["K"][0] == cam.fx and info["P"][2] == cam.cx


def test_raycaster_matches_analytic_shapes():
    shapes = [Shape("b", "box", (1.0, 1.0, 1.0), (3.0, 0.0, 0.5), (0.0, 0.0, math.pi / 4)),
              Shape("c", "cylinder", (0.5, 1.0), (0.0, 3.0, 0.5)),
              Shape("s", "sphere", (0.5,), (0.0, -3.0, 0.5))]
    rc = RayCaster(shapes)
    o = np.array([0.0, 0.0, 0.5])
    dirs = np.array([[1.0, 0, 0], [0, 1.0, 0], [0, -1.0, 0], [-1.0, 0, 0], [0, 0, -1.0]])
    t = rc.cast(o, dirs, 10.0)
    assert t == pytest.approx([3.0 - math.sqrt(0.5), 2.5, 2.5, math.inf, 0.5])
    assert rc.cast(o, dirs, 10.0, floor=False)[4] == math.inf
    assert rc.cast(np.array([3.0, 0.0, 0.5]), dirs[:1], 10.0)[0] == 0.0  # inside


def test_facade_names_and_errors(urdf):
    with BulletSim() as b:
        with pytest.raises(BulletError, match="no robot"):
            b.joint("wheel_left_joint")
        b.load_robot(urdf, Pose2D(0, 0, 0))
        assert set(b.movable_joints()) == {"wheel_left_joint", "wheel_right_joint"}
        with pytest.raises(BulletError, match="no joint 'nope'"):
            b.joint("nope")
        with pytest.raises(BulletError, match="no link 'nope'"):
            b.frame("nope")
        pos, rot = b.frame_pose("camera_depth_optical_frame")
        assert pos == pytest.approx([DEPTH_X, 0.0125, 0.26], abs=2e-3)
        assert rot[:, 2] == pytest.approx([1, 0, 0], abs=1e-3)   # optical z looks forward
        with pytest.raises(BulletError, match="valid XML"):
            BulletSim().load_robot("<robot", Pose2D(0, 0))


def test_urdf_without_sim_block_fails_clearly(urdf):
    import re
    bare = re.sub(r"<chefbot_sim.*</chefbot_sim>", "", urdf, flags=re.S)
    with pytest.raises(SimConfigError, match="chefbot_sim"):
        Simulator(bare, World("empty"))


def test_options_validation(urdf):
    with pytest.raises(SimConfigError, match="depth_fill"):
        Simulator(urdf, World("empty"), options=SimOptions(depth_fill="sometimes"))


def test_pacer():
    now = [0.0]
    p = Pacer(2.0, clock=lambda: now[0])
    assert p.delay(0.0) == 0.0
    assert p.delay(1.0) == pytest.approx(0.5)   # 1 s of sim at 2x wants 0.5 s of wall
    now[0] = 0.6
    assert p.delay(1.0) == 0.0
    assert Pacer(0.0).delay(100.0) == 0.0
    with pytest.raises(ValueError):
        Pacer(-1.0)


def test_pacer_without_catch_up():
    """Firmware mode: a sim that fell behind restarts its schedule instead of bursting."""
    now = [0.0]
    p = Pacer(1.0, clock=lambda: now[0], max_lag=0.02)
    assert p.delay(0.0) == 0.0
    now[0] = 0.51                                   # 10 ms behind: still on the old schedule
    assert p.delay(0.5) == 0.0
    assert p.delay(0.52) == pytest.approx(0.01)
    now[0] = 1.0                                    # 0.48 s behind: restart from here
    assert p.delay(0.52) == 0.0
    assert p.delay(0.6) == pytest.approx(0.08)      # paced at 1x again, no catch-up burst
    with pytest.raises(ValueError):
        Pacer(1.0, max_lag=-1.0)


def test_gui_without_display_is_a_clear_error(monkeypatch):
    monkeypatch.delenv("DISPLAY", raising=False)
    with pytest.raises(BulletError, match="gui:=true needs a display, but DISPLAY is not set"):
        BulletSim(gui=True)
    monkeypatch.setenv("DISPLAY", ":93")  # nothing listens there
    with pytest.raises(BulletError, match="cannot connect to the X server at DISPLAY=:93"):
        BulletSim(gui=True)


def test_float32_raycaster_matches_pybullet_rays_in_the_hotel(urdf, pkg):
    """The depth band's rays (float32 slab planes) against pybullet's own ray test."""
    from chefbot_sim.world import load_world
    sim = Simulator(urdf, load_world(pkg / "worlds" / "hotel.yaml"), Pose2D(1.5, 1.5, 0.5), SimOptions(seed=1))
    try:
        sim.step(24)
        pos, rot = sim.bullet.frame_pose(sim.params.depth_camera.depth_frame)
        dirs = sim._dirs_exact @ rot.T
        max_t = 8.0
        ours = sim._caster.cast(pos, dirs, max_t, floor=False)
        frac, ids = sim.bullet.cast_rays(np.repeat(pos[None, :], len(dirs), axis=0), pos + dirs * max_t)
        theirs = np.where(ids >= 0, frac * max_t, np.inf)
        assert np.isfinite(ours).sum() > 0.9 * len(ours)
        # pybullet's own box ray test differs by up to ~1 mm near edges (float64
        # slabs give the same differences) and may miss a grazing edge ray
        assert np.count_nonzero(np.isinf(ours) != np.isinf(theirs)) <= 0.005 * len(ours)
        both = np.isfinite(ours) & np.isfinite(theirs)
        assert np.max(np.abs(ours[both] - theirs[both])) < 1.5e-3
        assert np.median(np.abs(ours[both] - theirs[both])) < 1e-5
    finally:
        sim.close()


def test_float32_slabs_are_exact_enough_far_away():
    """A wall 7.9 m away, hit at a slant: float32 planes stay within 10 µm."""
    rc = RayCaster([Shape("w", "box", (0.2, 40.0, 2.0), (1000.0 + 8.0, 0.0, 1.0), (0.0, 0.0, 0.0))])
    o = np.array([1000.0, 0.0, 0.26])  # far from the world origin: shape-local origins keep precision
    dirs = np.array([[1.0, y, 0.0] for y in np.linspace(-0.55, 0.55, 101)])
    t = rc.cast(o, dirs, 10.0, floor=False)
    assert t == pytest.approx(np.full(101, 7.9), abs=1e-5)
