"""The image processing of the book's ``cv_bridge_demo.py`` (pure: numpy + OpenCV, no rospy).

Book, chapter 7: colour -> grey -> 7 x 7 blur -> Canny(15, 30) for the edges;
the depth image normalised to 0..1 (NORM_MINMAX) for display.  Ours checks its
inputs (the book's crashes on an empty or wrong-typed image) and makes the
depth normalisation NaN-safe (a Kinect/Astra depth image has NaN holes, which
make ``cv2.normalize`` return all NaN).
"""
from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np


class ImageError(ValueError):
    """An image the processing cannot use (the message says what is wrong)."""


@dataclass(frozen=True)
class EdgeParams:
    """Edge detection: blur kernel side (px, odd) and the Canny hysteresis thresholds (grey levels)."""

    blur_size: int = 7
    canny_low: float = 15.0      # [grey levels] Canny hysteresis low threshold (book: 15; 0 <= low <= high)
    canny_high: float = 30.0     # [grey levels] Canny hysteresis high threshold (book: 30)

    def __post_init__(self) -> None:
        if self.blur_size < 1 or self.blur_size % 2 == 0:
            raise ValueError(f"blur_size must be an odd number >= 1, got {self.blur_size}")
        if not 0 <= self.canny_low <= self.canny_high:
            raise ValueError(f"need 0 <= canny_low ({self.canny_low}) <= canny_high ({self.canny_high})")


def check_image(img: np.ndarray | None, what: str, channels: tuple[int, ...]) -> np.ndarray:
    """``img`` as an array with one of ``channels`` (1 = 2-D) or ImageError naming ``what``."""
    if img is None:
        raise ImageError(f"{what}: no image")
    a = np.asarray(img)
    if a.size == 0 or a.ndim < 2 or a.shape[0] == 0 or a.shape[1] == 0:
        raise ImageError(f"{what}: empty image (shape {a.shape})")
    ch = 1 if a.ndim == 2 else a.shape[2]
    if a.ndim > 3 or ch not in channels:
        raise ImageError(f"{what}: expected {' or '.join(map(str, channels))} channel(s), got shape {a.shape}")
    return a


def edges(bgr: np.ndarray, params: EdgeParams = EdgeParams()) -> np.ndarray:
    """The book's ``process_image``: uint8 (H, W) edge mask (255 = edge) of a BGR (or grey) uint8 image."""
    img = check_image(bgr, "edges", (1, 3))
    if img.dtype != np.uint8:
        raise ImageError(f"edges: expected an 8-bit image, got {img.dtype}")
    grey = img if img.ndim == 2 else cv2.cvtColor(img, cv2.COLOR_BGR2GRAY)
    grey = cv2.blur(grey, (params.blur_size, params.blur_size))
    return cv2.Canny(grey, params.canny_low, params.canny_high)


def depth_view(depth: np.ndarray) -> np.ndarray:
    """The book's ``process_depth_image``: depth (m, or mm for 16UC1) -> float32 0..1 (NORM_MINMAX).

    NaN, +/-inf and 0 (the drivers' "no reading") become 0; the finite
    readings are stretched to 0..1 (all equal -> 0).  An image without any
    reading comes back all 0.
    """
    d = check_image(depth, "depth_view", (1,))
    if not (np.issubdtype(d.dtype, np.floating) or np.issubdtype(d.dtype, np.integer)):
        raise ImageError(f"depth_view: expected a numeric depth image, got {d.dtype}")
    d = d.astype(np.float32, copy=False)
    valid = np.isfinite(d) & (d > 0)
    out = np.zeros(d.shape, np.float32)
    if valid.any():
        # a mask keeps the holes out of the min/max (cv2.normalize with NaN gives all NaN)
        cv2.normalize(np.where(valid, d, 0.0).astype(np.float32), out, 0.0, 1.0, cv2.NORM_MINMAX,
                      mask=valid.astype(np.uint8))
        out[~valid] = 0.0
        np.clip(out, 0.0, 1.0, out=out)   # NORM_MINMAX in float32 can undershoot 0 by ~1e-9
    return out


def depth_view_mono8(view: np.ndarray) -> np.ndarray:
    """A 0..1 view as uint8 0..255 (what image_view and image_saver show and save)."""
    return np.clip(np.nan_to_num(view) * 255.0 + 0.5, 0, 255).astype(np.uint8)
