"""The book's cv_bridge_demo processing on known images (no master)."""
import numpy as np
import pytest

from chefbot_vision.processing import EdgeParams, ImageError, depth_view, depth_view_mono8, edges


def test_edges_of_a_square_lie_on_its_border():
    img = np.zeros((120, 160, 3), np.uint8)
    img[40:80, 60:100] = (0, 200, 255)          # a bright square on black
    e = edges(img)
    assert e.dtype == np.uint8 and e.shape == (120, 160)
    ys, xs = np.nonzero(e)
    assert len(ys) > 100
    # every edge pixel lies within the blur's reach (3 px) of the square's border
    near_border = (np.minimum.reduce([np.abs(ys - 40), np.abs(ys - 79), np.abs(xs - 60), np.abs(xs - 99)]) <= 3)
    assert near_border.all()
    assert e[60, 80] == 0 and e[10, 10] == 0    # inside and outside: no edges
    # each side of the square has edges
    for r, c in ((40, 80), (79, 80), (60, 60), (60, 99)):
        assert e[r - 3:r + 4, c - 3:c + 4].any(), (r, c)


def test_uniform_image_has_no_edges_and_grey_input_works():
    assert not edges(np.full((50, 60, 3), 128, np.uint8)).any()
    grey = np.zeros((50, 60), np.uint8)
    grey[:, 30:] = 255
    assert edges(grey)[:, 26:34].any()


def test_thresholds_matter():
    img = np.zeros((60, 60, 3), np.uint8)
    img[:, 30:] = 60                              # a moderate step: above Canny(15, 30) after the 7x7 blur
    assert edges(img, EdgeParams(canny_low=15, canny_high=30)).any()
    assert not edges(img, EdgeParams(canny_low=500, canny_high=1000)).any()


@pytest.mark.parametrize("bad, what", [
    (None, "no image"), (np.zeros((0, 10, 3), np.uint8), "empty"), (np.zeros((10, 10, 4), np.uint8), "channel"),
    (np.zeros((10, 10, 3), np.float32), "8-bit")])
def test_edges_reject_bad_images(bad, what):
    with pytest.raises(ImageError, match=what):
        edges(bad)


def test_edge_params_validated():
    with pytest.raises(ValueError, match="odd"):
        EdgeParams(blur_size=4)
    with pytest.raises(ValueError, match="canny_low"):
        EdgeParams(canny_low=40, canny_high=30)


def test_depth_view_normalises_and_survives_nan():
    d = np.array([[1.0, 2.0, np.nan], [3.0, np.inf, 0.0]], np.float32)
    v = depth_view(d)
    assert v.dtype == np.float32 and np.isfinite(v).all()
    np.testing.assert_allclose(v, [[0.0, 0.5, 0.0], [1.0, 0.0, 0.0]], atol=1e-6)
    assert not depth_view(np.full((4, 4), np.nan, np.float32)).any()      # no reading at all: zeros
    assert not depth_view(np.full((4, 4), 2.0, np.float32)).any()         # all equal: zeros
    mm = np.array([[0, 1000], [2000, 3000]], np.uint16)                   # 16UC1 millimetres, 0 = none
    np.testing.assert_allclose(depth_view(mm), [[0, 0], [0.5, 1.0]], atol=1e-6)
    assert depth_view_mono8(v).tolist() == [[0, 128, 0], [255, 0, 0]]


def test_depth_view_stays_within_0_1():
    # cv2's float32 NORM_MINMAX maps this frame's nearest reading to -2.3e-9 (seen in camera.test)
    d = np.random.default_rng(0).uniform(0.5, 8.0, (2, 4, 4)).astype(np.float32)[1]
    v = depth_view(d)
    assert v.min() == 0.0 and v.max() == pytest.approx(1.0, abs=1e-6)


@pytest.mark.parametrize("bad, what", [
    (np.zeros((0, 4), np.float32), "empty"), (np.zeros((4, 4, 3), np.float32), "channel"),
    (np.array([["a"]]), "numeric")])
def test_depth_view_rejects_bad_images(bad, what):
    with pytest.raises(ImageError, match=what):
        depth_view(bad)
