"""Camera and image sources of the chapter-7 nodes (pure: OpenCV, no rospy).

* :func:`load_image`: an image file as BGR (``image_read``), errors naming the file;
* :class:`Capture`: OpenCV ``VideoCapture`` of a device index (``0`` = /dev/video0)
  or a video file (``cam``, the book's camera loop made a usb_cam-like node),
  with a clear error when the device or file does not exist;
* :func:`pinhole_guess`: intrinsics from a horizontal field of view when no
  calibration file is given.
"""
from __future__ import annotations

import math
import os
from dataclasses import dataclass

import cv2
import numpy as np


class SourceError(RuntimeError):
    """A camera, video or image that cannot be opened or read (names it)."""


def load_image(path: str, flags: int = cv2.IMREAD_COLOR) -> np.ndarray:
    """The image at ``path`` (BGR uint8 by default); SourceError when missing or not an image."""
    if not path:
        raise SourceError("image_read: no image file given (param ~image)")
    if not os.path.isfile(path):
        raise SourceError(f"image_read: no such file: {path}")
    img = cv2.imread(path, flags)
    if img is None or img.size == 0:
        raise SourceError(f"image_read: OpenCV cannot read an image from {path} (not an image, or unsupported)")
    return img


def parse_device(device: str | int) -> int | str:
    """A device index (int or digits) stays an int; '/dev/videoN' or a file path stays a path."""
    if isinstance(device, bool):
        raise SourceError(f"cam: device must be an index or a path, got {device!r}")
    if isinstance(device, int):
        return device
    s = str(device).strip()
    if not s:
        raise SourceError("cam: device is empty (give an index such as 0, /dev/video0, or a video file)")
    return int(s) if s.isdigit() else s


@dataclass(frozen=True)
class CaptureParams:
    """``cam`` settings: source, requested size (px, 0 = the device's), frame rate (Hz), loop a file."""

    device: str = "0"
    width: int = 640        # [px] frame width asked of a device, frames resized to it (0 = as given; >= 0)
    height: int = 480       # [px] frame height, as width (0 = as given; >= 0)
    rate: float = 30.0      # [Hz] frames published per second; a video file is played at this rate (> 0)
    loop: bool = True

    def __post_init__(self) -> None:
        if self.width < 0 or self.height < 0:
            raise ValueError(f"width and height must be >= 0 (0 = as the device gives), "
                             f"got {self.width} x {self.height}")
        if not (math.isfinite(self.rate) and self.rate > 0):
            raise ValueError(f"rate must be > 0 Hz, got {self.rate}")


class Capture:
    """An open VideoCapture; :meth:`read` gives BGR frames of the requested size."""

    def __init__(self, params: CaptureParams) -> None:
        self.params = params
        self.source = parse_device(params.device)
        self.is_file = isinstance(self.source, str) and not self.source.startswith("/dev/")
        if isinstance(self.source, str) and not os.path.exists(self.source):
            kind = "camera device" if not self.is_file else "video file"
            raise SourceError(f"cam: no such {kind}: {self.source}")
        if isinstance(self.source, int) and not os.path.exists(f"/dev/video{self.source}"):
            raise SourceError(f"cam: camera {self.source} does not exist (/dev/video{self.source} is missing; "
                              "is the camera plugged in and are you in group 'video'?)")
        self.cap = cv2.VideoCapture(self.source)
        if not self.cap.isOpened():
            raise SourceError(f"cam: OpenCV cannot open {self.source!r} (busy, no permission, or not a video)")
        if not self.is_file and params.width and params.height:
            self.cap.set(cv2.CAP_PROP_FRAME_WIDTH, params.width)
            self.cap.set(cv2.CAP_PROP_FRAME_HEIGHT, params.height)

    def read(self) -> np.ndarray | None:
        """The next frame (BGR uint8), resized to width x height when those are set; None at the end
        of a file that does not loop.  SourceError when a device stops delivering."""
        ok, frame = self.cap.read()
        if (not ok or frame is None) and self.is_file and self.params.loop:
            self.cap.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self.cap.read()
        if not ok or frame is None:
            if self.is_file:
                return None
            raise SourceError(f"cam: camera {self.source!r} delivered no frame (unplugged?)")
        w, h = self.params.width, self.params.height
        if w and h and (frame.shape[1], frame.shape[0]) != (w, h):
            frame = cv2.resize(frame, (w, h), interpolation=cv2.INTER_AREA)
        return frame

    def close(self) -> None:
        """Release the camera."""
        self.cap.release()


def pinhole_guess(width: int, height: int, horizontal_fov_deg: float = 60.0) -> tuple[float, float, float, float]:
    """(fx, fy, cx, cy) in px of an uncalibrated camera with square pixels and the given horizontal FOV."""
    if not 0 < horizontal_fov_deg < 180:
        raise ValueError(f"horizontal_fov must be in (0, 180) degrees, got {horizontal_fov_deg}")
    f = (width / 2.0) / math.tan(math.radians(horizontal_fov_deg) / 2.0)
    return f, f, (width - 1) / 2.0, (height - 1) / 2.0
