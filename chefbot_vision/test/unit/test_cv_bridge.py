"""Debian's cv_bridge round trips for every encoding our nodes use (no master)."""
import numpy as np
import pytest

cv_bridge = pytest.importorskip("cv_bridge", reason="python3-cv-bridge (tools/apt-packages.txt) not installed")
CvBridge, CvBridgeError = cv_bridge.CvBridge, cv_bridge.CvBridgeError


@pytest.fixture
def bridge():
    return CvBridge()


def test_bgr8_rgb8_round_trip(bridge):
    bgr = np.random.default_rng(1).integers(0, 255, (24, 32, 3), dtype=np.uint8)
    m = bridge.cv2_to_imgmsg(bgr, "bgr8")
    assert (m.encoding, m.width, m.height, m.step) == ("bgr8", 32, 24, 96)
    np.testing.assert_array_equal(bridge.imgmsg_to_cv2(m, "bgr8"), bgr)
    np.testing.assert_array_equal(bridge.imgmsg_to_cv2(m, "rgb8"), bgr[:, :, ::-1])
    # the simulator publishes rgb8 (chefbot_sim.ros_io.rgb_to_image); the demo asks for bgr8
    from chefbot_sim.ros_io import rgb_to_image
    sim_msg = rgb_to_image(bgr[:, :, ::-1].copy(), None, "cam")
    np.testing.assert_array_equal(bridge.imgmsg_to_cv2(sim_msg, "bgr8"), bgr)


def test_mono8_and_32fc1_round_trip(bridge):
    mono = np.arange(12, dtype=np.uint8).reshape(3, 4)
    np.testing.assert_array_equal(bridge.imgmsg_to_cv2(bridge.cv2_to_imgmsg(mono, "mono8")), mono)
    depth = np.array([[0.5, np.nan], [np.inf, 7.25]], np.float32)
    back = bridge.imgmsg_to_cv2(bridge.cv2_to_imgmsg(depth, "32FC1"), "passthrough")
    assert back.dtype == np.float32
    np.testing.assert_array_equal(np.isnan(back), np.isnan(depth))
    assert back[0, 0] == 0.5 and back[1, 1] == 7.25 and np.isposinf(back[1, 0])
    # the simulator's depth images (chefbot_bringup.ros_io.depth_to_image) read back exactly
    from chefbot_sim.ros_io import depth_to_image
    np.testing.assert_array_equal(bridge.imgmsg_to_cv2(depth_to_image(depth, None, "d"), "32FC1")[0, 0], 0.5)


def test_16uc1_passthrough_and_bad_conversions(bridge):
    mm = np.array([[0, 1000]], np.uint16)
    np.testing.assert_array_equal(bridge.imgmsg_to_cv2(bridge.cv2_to_imgmsg(mm, "16UC1")), mm)
    with pytest.raises(CvBridgeError):
        bridge.imgmsg_to_cv2(bridge.cv2_to_imgmsg(mm, "16UC1"), "bgr8")   # depth is not colour
    with pytest.raises(CvBridgeError):
        bridge.cv2_to_imgmsg(np.zeros((2, 2), np.float32), "bgr8")         # one channel is not bgr8


def test_compressed_round_trip(bridge):
    img = np.zeros((16, 16, 3), np.uint8)
    img[4:12, 4:12] = 255
    cm = bridge.cv2_to_compressed_imgmsg(img, "png")
    np.testing.assert_array_equal(bridge.compressed_imgmsg_to_cv2(cm), img)
