"""Depth -> point cloud against the pinhole model; PointCloud2 packing read back by Debian's reader."""
import numpy as np
import pytest
from sensor_msgs import point_cloud2

from chefbot_vision.cloud import CloudError, Pinhole, depth_to_points, transform_points
from chefbot_vision.ros_io import camera_info, cloud_msg, cloud_xyz, pinhole_from_info

CAM = Pinhole(160, 120, 140.0, 140.0, 79.5, 59.5)


def test_points_follow_the_pinhole_model():
    depth = np.full((120, 160), 2.0, np.float32)
    pts = depth_to_points(depth, CAM)
    assert pts.shape == (120, 160, 3) and pts.dtype == np.float32
    for v, u in ((0, 0), (59, 80), (119, 159), (10, 150)):
        x, y, z = pts[v, u]
        assert z == 2.0
        assert x == pytest.approx((u - 79.5) * 2.0 / 140.0, rel=1e-6)
        assert y == pytest.approx((v - 59.5) * 2.0 / 140.0, rel=1e-6)
        # projecting back gives the pixel
        assert CAM.fx * x / z + CAM.cx == pytest.approx(u, abs=1e-4)


def test_invalid_pixels_and_ranges_become_nan():
    depth = np.full((120, 160), 2.0, np.float32)
    depth[0, 0], depth[0, 1], depth[0, 2], depth[0, 3] = np.nan, np.inf, 0.3, 9.0
    pts = depth_to_points(depth, CAM, min_range=0.45, max_range=8.0)
    assert np.isnan(pts[0, :4]).all() and np.isfinite(pts[0, 4]).all()
    mm = np.zeros((120, 160), np.uint16)
    mm[5, 5] = 1500
    p = depth_to_points(mm, CAM, depth_scale=0.001)
    assert p[5, 5, 2] == pytest.approx(1.5) and np.isnan(p[0, 0]).all()


def test_stride_decimates_with_matching_intrinsics():
    depth = np.random.default_rng(0).uniform(1, 3, (120, 160)).astype(np.float32)
    full = depth_to_points(depth, CAM)
    dec = depth_to_points(depth, CAM, stride=4)
    assert dec.shape == (30, 40, 3)
    np.testing.assert_allclose(dec, full[::4, ::4], rtol=1e-6)
    assert CAM.decimated(4).width == 40


@pytest.mark.parametrize("depth, what", [
    (np.zeros((100, 160), np.float32), "camera_info says"), (np.zeros((0,), np.float32), "2-D")])
def test_bad_depth_images(depth, what):
    with pytest.raises(CloudError, match=what):
        depth_to_points(depth, CAM)
    with pytest.raises(CloudError, match="stride"):
        depth_to_points(np.zeros((120, 160), np.float32), CAM, stride=0)


def test_bad_intrinsics():
    with pytest.raises(CloudError, match="focal"):
        Pinhole(10, 10, 0.0, 1.0, 5, 5)
    with pytest.raises(CloudError, match="K must"):
        Pinhole.from_camera_info(10, 10, [], [0.0] * 12)


def test_cloud_message_reads_back_with_debian_point_cloud2():
    depth = np.full((6, 8), 1.5, np.float32)
    depth[0, 0] = np.nan
    cam = Pinhole(8, 6, 7.0, 7.0, 3.5, 2.5)
    pts = depth_to_points(depth, cam)
    m = cloud_msg(pts, None, "camera_depth_optical_frame")
    assert (m.width, m.height, m.point_step, m.is_dense) == (8, 6, 12, False)
    ref = np.array(list(point_cloud2.read_points(m, field_names=("x", "y", "z"))), np.float32)
    np.testing.assert_array_equal(np.isnan(ref), np.isnan(pts.reshape(-1, 3)))
    np.testing.assert_allclose(ref[1:], pts.reshape(-1, 3)[1:])
    np.testing.assert_allclose(cloud_xyz(m)[1:], ref[1:])
    rgb = np.zeros((6, 8, 3), np.uint8)
    rgb[..., 0], rgb[..., 1], rgb[..., 2] = 255, 128, 1
    mc = cloud_msg(pts, None, "camera_rgb_optical_frame", rgb)
    assert mc.point_step == 16 and [f.name for f in mc.fields] == ["x", "y", "z", "rgb"]
    packed = np.array(list(point_cloud2.read_points(mc, field_names=("rgb",))), np.float32).view(np.uint32)
    assert (packed == 0xFF8001).all()
    np.testing.assert_allclose(cloud_xyz(mc)[1:], ref[1:])      # xyz also read from an xyzrgb layout


def test_cloud_xyz_rejects_bad_messages():
    m = cloud_msg(np.zeros((2, 2, 3), np.float32), None, "f")
    m.data = m.data[:10]
    with pytest.raises(CloudError, match="too short"):
        cloud_xyz(m)
    m.fields = m.fields[:2]
    with pytest.raises(CloudError, match="field 'z'"):
        cloud_xyz(m)
    with pytest.raises(CloudError, match=r"\(H, W, 3\)"):
        cloud_msg(np.zeros((4, 3), np.float32), None, "f")


def test_camera_info_helpers():
    info = camera_info(160, 120, 140.0, 140.0, 79.5, 59.5, "cam")
    assert pinhole_from_info(info) == CAM
    # a depth image whose size is not camera_info's is refused, naming both sizes
    with pytest.raises(CloudError, match="depth image is 320 x 240 but camera_info says 160 x 120"):
        depth_to_points(np.zeros((240, 320), np.float32), pinhole_from_info(info))


def test_transform_points_drops_nan():
    pts = np.array([[[1.0, 0.0, 0.0], [np.nan, 0, 0]]], np.float32)
    rot = np.array([[0, -1, 0], [1, 0, 0], [0, 0, 1]], float)
    out = transform_points(pts, rot, np.array([0.0, 0.0, 0.5]))
    np.testing.assert_allclose(out, [[0.0, 1.0, 0.5]])


def test_pinhole_agrees_with_image_geometry():
    """The book-era PinholeCameraModel (Debian's python3-image-geometry) gives the same rays."""
    image_geometry = pytest.importorskip("image_geometry")
    model = image_geometry.PinholeCameraModel()
    model.fromCameraInfo(camera_info(160, 120, 140.0, 141.0, 79.5, 59.5, "cam"))
    cam = Pinhole(160, 120, 140.0, 141.0, 79.5, 59.5)
    pts = depth_to_points(np.full((120, 160), 1.0, np.float32), cam)
    for u, v in ((0, 0), (100, 30), (159, 119)):
        ray = np.array(model.projectPixelTo3dRay((u, v)))
        np.testing.assert_allclose(pts[v, u], ray / ray[2], rtol=1e-5)
