"""image_read's loader and cam's VideoCapture source (no master, no camera needed)."""
import cv2
import numpy as np
import pytest

from chefbot_vision.capture import Capture, CaptureParams, SourceError, load_image, parse_device, pinhole_guess


def test_load_image_and_errors(tmp_path):
    p = tmp_path / "a.png"
    img = np.zeros((10, 12, 3), np.uint8)
    img[2:5, 3:6] = (10, 20, 30)
    cv2.imwrite(str(p), img)
    np.testing.assert_array_equal(load_image(str(p)), img)
    with pytest.raises(SourceError, match="no such file: .*missing.png"):
        load_image(str(tmp_path / "missing.png"))
    bad = tmp_path / "bad.png"
    bad.write_text("not an image")
    with pytest.raises(SourceError, match="cannot read an image from .*bad.png"):
        load_image(str(bad))
    with pytest.raises(SourceError, match="no image file given"):
        load_image("")


def test_parse_device():
    assert parse_device("0") == 0 and parse_device(2) == 2
    assert parse_device("/dev/video1") == "/dev/video1" and parse_device(" clip.avi ") == "clip.avi"
    with pytest.raises(SourceError, match="empty"):
        parse_device(" ")


def test_missing_sources_say_what_is_missing(tmp_path):
    with pytest.raises(SourceError, match="no such video file: .*nothing.avi"):
        Capture(CaptureParams(device=str(tmp_path / "nothing.avi")))
    with pytest.raises(SourceError, match="camera 57 does not exist"):
        Capture(CaptureParams(device="57"))
    with pytest.raises(SourceError, match="no such camera device: /dev/video57"):
        Capture(CaptureParams(device="/dev/video57"))
    with pytest.raises(ValueError, match="rate"):
        CaptureParams(rate=0)


def test_video_file_frames_resized_and_looped(tmp_path):
    path = str(tmp_path / "clip.avi")
    w = cv2.VideoWriter(path, cv2.VideoWriter_fourcc(*"MJPG"), 10, (64, 48))
    if not w.isOpened():
        pytest.skip("this OpenCV build cannot write MJPG AVI")
    for i in range(3):
        w.write(np.full((48, 64, 3), 60 * i, np.uint8))
    w.release()
    cap = Capture(CaptureParams(device=path, width=32, height=24, loop=True))
    frames = [cap.read() for _ in range(5)]       # 3 frames, then it starts again
    assert all(f is not None and f.shape == (24, 32, 3) for f in frames)
    cap.close()
    once = Capture(CaptureParams(device=path, width=0, height=0, loop=False))
    assert [once.read() is None for _ in range(4)] == [False, False, False, True]


def test_pinhole_guess():
    fx, fy, cx, cy = pinhole_guess(640, 480, 90.0)
    assert fx == pytest.approx(320.0) and (cx, cy) == (319.5, 239.5)
    with pytest.raises(ValueError):
        pinhole_guess(640, 480, 0)
