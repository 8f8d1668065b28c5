"""The simulated RGB-D camera: RGB render, registered depth, dense depth and clouds (DIRECT mode, no master)."""
import numpy as np
import pytest

from chefbot_common.geometry import Pose2D
from chefbot_sim.camera import registered_cloud
from chefbot_sim.sim import SimConfigError, SimOptions, Simulator
from chefbot_sim.world import parse_yaml_world
from chefbot_vision.cloud import depth_to_points

# a grey wall 2.9 m ahead (near face), a red box on the left and a blue box on the right, nearer
SCENE = parse_yaml_world("""
objects:
  - {name: wall, shape: box, size: [0.2, 6.0, 1.0], pose: [3.0, 0.0, 0.0], colour: [0.5, 0.5, 0.5]}
  - {name: red, shape: box, size: [0.3, 0.3, 0.6], pose: [1.8, 0.45, 0.0], colour: [0.9, 0.1, 0.1]}
  - {name: blue, shape: box, size: [0.3, 0.3, 0.6], pose: [1.8, -0.45, 0.0], colour: [0.1, 0.1, 0.9]}
""")
DEPTH_X = 0.1615   # m, camera_depth_frame ahead of base_footprint (chefbot.xacro)


@pytest.fixture(scope="module")
def sim(urdf):
    s = Simulator(urdf, SCENE, options=SimOptions(seed=1))
    yield s
    s.close()


def test_rgb_image_size_and_colours(sim):
    img = sim.rgb_image()
    cam = sim.rgb_camera
    assert img.shape == (240, 320, 3) and (cam.width, cam.height) == (320, 240)
    mid = cam.height // 2
    left, right = img[mid, : cam.width // 3], img[mid, 2 * cam.width // 3:]
    # the red box is on the left (+y), the blue one on the right, the wall grey, the floor light
    assert ((left[:, 0] > 150) & (left[:, 2] < 80)).sum() > 10
    assert ((right[:, 2] > 150) & (right[:, 0] < 80)).sum() > 10
    centre = img[mid - 20, cam.width // 2].astype(int)      # wall between the boxes, above the floor
    assert abs(centre[0] - centre[2]) < 20 and 60 < centre[0] < 200
    floor = img[-1, cam.width // 2].astype(int)
    assert floor.min() > 150 and not np.array_equal(floor, centre)


def test_registered_depth_and_cloud_match_the_scene(sim):
    sim.rgb_image()
    frame = sim.last_rgb
    cam = sim.rgb_camera
    mid = cam.height // 2
    # the wall's near face is 2.9 m from the base; the rgb camera sits ~DEPTH_X ahead
    assert frame.depth[mid - 20, cam.width // 2] == pytest.approx(2.9 - DEPTH_X, abs=0.02)
    pts, colours = registered_cloud(frame, cam, 2)
    assert pts.shape == (120, 160, 3) and colours.shape == (120, 160, 3)
    red = (colours[..., 0] > 150) & (colours[..., 2] < 80) & np.isfinite(pts[..., 2])
    # the red box's points: left of the optical axis (x < 0 in the optical frame), 1.65 m ahead of the base
    assert red.sum() > 20
    assert np.median(pts[red][:, 0]) < -0.2
    assert np.median(pts[red][:, 2]) == pytest.approx(1.65 - DEPTH_X, abs=0.05)


def cast_and_dense_depth(sim) -> tuple[np.ndarray, np.ndarray]:
    """The depth image ray-cast (band + coarse) and rendered in full, at the same pose."""
    sim.dense_depth = False
    cast = sim.depth_image()
    sim.dense_depth = True
    try:
        return cast, sim.depth_image()
    finally:
        sim.dense_depth = False


def test_dense_depth_agrees_with_the_ray_caster(sim):
    sim.teleport(Pose2D(0.0, 0.0, 0.0))
    cast, dense = cast_and_dense_depth(sim)
    rows = sim._band_rows
    both = np.isfinite(cast[rows]) & np.isfinite(dense[rows])
    assert both.mean() > 0.9
    # 5 mm depth noise on both; the renderer's z-buffer is exact within ~1 mm
    assert np.median(np.abs(cast[rows][both] - dense[rows][both])) < 0.01
    # every pixel measured (rows above the wall's top see nothing, as the ray caster's do)
    assert abs(np.isfinite(dense).mean() - np.isfinite(cast).mean()) < 0.03


def test_depth_cloud_of_the_wall(sim):
    sim.dense_depth = True
    try:
        depth = sim.depth_image()
    finally:
        sim.dense_depth = False
    pts = depth_to_points(depth, sim.depth_camera)
    wall = pts[np.abs(pts[..., 0]) < 0.1]               # the column strip between the boxes
    wall = wall[np.isfinite(wall).all(axis=1) & (wall[:, 1] < 0.1)]   # at or above the camera
    assert np.median(wall[:, 2]) == pytest.approx(2.9 - DEPTH_X, abs=0.02)


def test_registered_stride_validated():
    with pytest.raises(SimConfigError, match="registered_stride"):
        SimOptions(registered_stride=0).validate()


def test_dense_depth_keeps_the_exact_scan_band(sim):
    """With the rendered (dense) depth on, the rows depth_to_scan reads are still the exact ray cast:
    the renderer's depth differs at object edges, which moved amcl off its route."""
    cast, dense = cast_and_dense_depth(sim)
    band = slice(sim._depth_rows[0], sim._depth_rows[-1] + 1)
    a, b = cast[band], dense[band]
    np.testing.assert_array_equal(np.isfinite(a), np.isfinite(b))
    noise = sim.params.depth_camera.noise_stddev
    assert np.nanmax(np.abs(a - b)) <= 8 * noise + 1e-6
    # outside the band the rendered image is dense where the cast one is coarse
    assert np.isfinite(dense).sum() >= np.isfinite(cast).sum()
