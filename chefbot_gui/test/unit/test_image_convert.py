"""sensor_msgs/Image fields → display RGB (no ROS, no Qt)."""
from __future__ import annotations

import numpy as np
import pytest

from chefbot_gui.image_convert import SUPPORTED_ENCODINGS, ImageError, to_display


def test_rgb8_and_bgr8_give_the_same_colours() -> None:
    rgb = np.array([[[255, 0, 0], [0, 255, 0]], [[0, 0, 255], [10, 20, 30]]], np.uint8)
    out = to_display("rgb8", 2, 2, 6, rgb.tobytes())
    assert np.array_equal(out.rgb, rgb) and out.rgb.flags.c_contiguous
    assert out.note == "2×2 rgb8"
    assert np.array_equal(to_display("bgr8", 2, 2, 6, rgb[:, :, ::-1].tobytes()).rgb, rgb)
    assert np.array_equal(to_display("bgra8", 2, 2, 8, np.dstack([rgb[:, :, ::-1], np.zeros((2, 2), np.uint8)])
                                     .tobytes()).rgb, rgb)


def test_row_padding_is_skipped() -> None:
    rows = [bytes([1, 2, 3, 99]), bytes([4, 5, 6, 99])]  # mono8, width 3, step 4
    out = to_display("mono8", 3, 2, 4, b"".join(rows))
    assert out.rgb.shape == (2, 3, 3)
    assert out.rgb[:, :, 0].tolist() == [[1, 2, 3], [4, 5, 6]]
    assert np.array_equal(out.rgb[:, :, 0], out.rgb[:, :, 2])


def test_16uc1_depth_is_normalised_and_zero_is_black() -> None:
    depth = np.array([[0, 500], [1000, 2000]], np.uint16)
    out = to_display("16UC1", 2, 2, 4, depth.tobytes())
    g = out.rgb[:, :, 0]
    assert g[0, 0] == 0 and g[0, 1] == 1 and g[1, 1] == 255 and 1 < g[1, 0] < 255
    assert "500–2000 mm" in out.note
    big = depth.astype(">u2").tobytes()
    assert np.array_equal(to_display("16UC1", 2, 2, 4, big, is_bigendian=True).rgb, out.rgb)


def test_32fc1_depth_ignores_nan_and_inf() -> None:
    depth = np.array([[np.nan, 1.0], [np.inf, 3.0]], np.float32)
    out = to_display("32FC1", 2, 2, 8, depth.tobytes())
    assert out.rgb[:, :, 0].tolist() == [[0, 1], [0, 255]]
    flat = to_display("32FC1", 2, 1, 8, np.array([2.0, 2.0], np.float32).tobytes())
    assert flat.rgb[:, :, 0].tolist() == [[255, 255]]
    none = to_display("32FC1", 1, 1, 4, np.array([np.nan], np.float32).tobytes())
    assert none.rgb.sum() == 0 and "no valid values" in none.note


@pytest.mark.parametrize(("args", "match"), [
    (("yuv422", 2, 2, 4, b"\0" * 8), "unsupported encoding 'yuv422'"),
    (("rgb8", 0, 0, 0, b""), r"empty image \(0×0\)"),
    (("rgb8", 4, 0, 12, b""), "empty image"),
    (("rgb8", 2, 2, 5, b"\0" * 12), "step 5 B is shorter"),
    (("rgb8", 2, 2, 6, b"\0" * 11), "data has 11 B"),
    (("mono8", 100_000, 100_000, 100_000, b""), "too large"),
])
def test_bad_images_raise_a_clear_error(args, match) -> None:
    with pytest.raises(ImageError, match=match):
        to_display(*args)


def test_every_supported_encoding_converts() -> None:
    sizes = {"u1": 1, "u2": 2, "f4": 4}
    from chefbot_gui.image_convert import _FORMATS
    for enc in SUPPORTED_ENCODINGS:
        ch, kind, _ = _FORMATS[enc]
        step = 3 * ch * sizes[kind]
        out = to_display(enc, 3, 2, step, bytes(range(step * 2)))
        assert out.rgb.shape == (2, 3, 3) and out.rgb.dtype == np.uint8
