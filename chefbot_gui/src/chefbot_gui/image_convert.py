"""``sensor_msgs/Image`` fields → an RGB array to display (pure: numpy, no rospy, no Qt).

Colour images (``rgb8``, ``bgr8``, ``rgba8``, ``bgra8``, ``8UC3`` read as
OpenCV's BGR) are shown as they are; ``mono8``/``8UC1`` as grey; 16-bit
(``16UC1``/``mono16``, depth in mm) and float (``32FC1``, depth in m) images
are normalised for display: the smallest valid value black, the largest white,
where 0, NaN and ±inf count as "no data" (drawn black, as rqt_image_view's
depth view does).  Anything else raises :class:`ImageError` with a message
naming the problem.
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from chefbot_gui.topic_stats import Stats

IMAGE_TYPE = "sensor_msgs/Image"

# encoding → (channels, numpy dtype, channel order for RGB display or None for one channel)
_FORMATS: dict[str, tuple[int, str, tuple[int, ...] | None]] = {
    "rgb8": (3, "u1", (0, 1, 2)),
    "bgr8": (3, "u1", (2, 1, 0)),
    "8UC3": (3, "u1", (2, 1, 0)),
    "rgba8": (4, "u1", (0, 1, 2)),
    "bgra8": (4, "u1", (2, 1, 0)),
    "8UC4": (4, "u1", (2, 1, 0)),
    "mono8": (1, "u1", None),
    "8UC1": (1, "u1", None),
    "mono16": (1, "u2", None),
    "16UC1": (1, "u2", None),
    "32FC1": (1, "f4", None),
}
SUPPORTED_ENCODINGS = tuple(_FORMATS)
MAX_PIXELS = 50_000_000  # refuse absurd sizes before allocating (a 7k × 7k image)


class ImageError(ValueError):
    """The image cannot be shown; the message says why."""


@dataclass(frozen=True)
class DisplayImage:
    """``rgb``: H×W×3 uint8, C-contiguous; ``note``: what the viewer should say (size, encoding, range)."""

    rgb: np.ndarray
    note: str


@dataclass(frozen=True)
class ImageFrame:
    """The image view's latest state: ``serial`` grows with every frame or topic change;
    ``image`` to show, or ``error`` saying why not; ``stats``: the topic's traffic."""

    serial: int = 0
    topic: str = ""
    image: DisplayImage | None = None
    error: str = ""
    stats: Stats = Stats()


def to_display(encoding: str, width: int, height: int, step: int, data: bytes,
               is_bigendian: bool = False) -> DisplayImage:
    """Convert the fields of a ``sensor_msgs/Image`` for display; raises :class:`ImageError`."""
    if encoding not in _FORMATS:
        raise ImageError(f"unsupported encoding {encoding!r} (supported: {', '.join(SUPPORTED_ENCODINGS)})")
    if width <= 0 or height <= 0:
        raise ImageError(f"empty image ({width}×{height})")
    if width * height > MAX_PIXELS:
        raise ImageError(f"image too large to show ({width}×{height})")
    channels, kind, order = _FORMATS[encoding]
    dtype = np.dtype(kind).newbyteorder(">" if is_bigendian else "<")
    row_bytes = width * channels * dtype.itemsize
    if step < row_bytes:
        raise ImageError(f"step {step} B is shorter than a row of {width} {encoding} pixels ({row_bytes} B)")
    if len(data) < step * height:
        raise ImageError(f"data has {len(data)} B, {encoding} {width}×{height} with step {step} needs "
                         f"{step * height} B")
    raw = np.frombuffer(data, dtype=np.uint8, count=step * height).reshape(height, step)[:, :row_bytes]
    px = np.ascontiguousarray(raw).view(dtype).reshape(height, width, channels)
    size = f"{width}×{height} {encoding}"
    if order is not None:
        return DisplayImage(np.ascontiguousarray(px[:, :, list(order)]), size)
    plane = px[:, :, 0]
    if kind == "u1":
        grey = plane
        note = size
    else:
        grey, note = _normalise(plane, size, {"16UC1": " mm", "32FC1": " m"}.get(encoding, ""))
    return DisplayImage(np.ascontiguousarray(np.repeat(grey[:, :, None], 3, axis=2)), note)


def _normalise(plane: np.ndarray, size: str, unit: str) -> tuple[np.ndarray, str]:
    """Scale valid values (finite, non-zero) to 1..255; invalid ones to 0."""
    values = plane.astype(np.float64)
    valid = np.isfinite(values) & (values != 0)
    if not valid.any():
        return np.zeros(plane.shape, np.uint8), f"{size}, no valid values (all 0/NaN)"
    lo, hi = float(values[valid].min()), float(values[valid].max())
    out = np.zeros(plane.shape, np.uint8)
    if hi > lo:
        out[valid] = np.rint(1 + (values[valid] - lo) * (254.0 / (hi - lo))).astype(np.uint8)
    else:
        out[valid] = 255
    return out, f"{size}, {lo:.4g}–{hi:.4g}{unit} shown black→white, 0/NaN black"
