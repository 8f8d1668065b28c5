"""Depth image -> 3-D points with the pinhole model (pure numpy, no ROS).

What ``depth_image_proc/point_cloud_xyz`` and ``point_cloud_xyzrgb`` compute,
vectorised: pixel (u, v) with depth z (m, along the optical axis) is the point

    x = (u - cx) * z / fx,   y = (v - cy) * z / fy,   z

in the camera's optical frame (x right, y down, z forward).  Clouds stay
*organised* (one point per pixel, row-major, NaN where there is no reading),
as the Kinect/Astra drivers publish them; ``stride`` keeps every stride-th
pixel in both directions (the intrinsics are scaled to match).
"""
from __future__ import annotations

from dataclasses import dataclass

import numpy as np


class CloudError(ValueError):
    """Inputs that cannot make a point cloud (the message names the problem)."""


@dataclass(frozen=True)
class Pinhole:
    """Pinhole intrinsics in pixels for an image of ``width`` x ``height``."""

    width: int
    height: int
    fx: float
    fy: float
    cx: float
    cy: float

    def __post_init__(self) -> None:
        if self.width < 1 or self.height < 1:
            raise CloudError(f"camera size must be positive, got {self.width} x {self.height}")
        if not (np.isfinite(self.fx) and np.isfinite(self.fy) and self.fx > 0 and self.fy > 0):
            raise CloudError(f"camera focal lengths must be finite and > 0, got fx={self.fx}, fy={self.fy}")

    @classmethod
    def from_camera_info(cls, width: int, height: int, k: list[float], p: list[float] | None = None) -> Pinhole:
        """From CameraInfo's size, ``K`` (3x3) and ``P`` (3x4, preferred when set: rectified images)."""
        if p is not None and len(p) == 12 and p[0] != 0.0:
            return cls(int(width), int(height), p[0], p[5], p[2], p[6])
        if k is None or len(k) != 9:
            raise CloudError(f"camera_info K must have 9 elements, got {None if k is None else len(k)}")
        return cls(int(width), int(height), k[0], k[4], k[2], k[5])

    def decimated(self, stride: int) -> Pinhole:
        """Intrinsics of the image that keeps pixels 0, stride, 2*stride, ... in both directions."""
        if stride == 1:
            return self
        return Pinhole(len(range(0, self.width, stride)), len(range(0, self.height, stride)),
                       self.fx / stride, self.fy / stride, self.cx / stride, self.cy / stride)


def _unit_rays(cam: Pinhole, stride: int) -> tuple[np.ndarray, np.ndarray]:
    u = np.arange(0, cam.width, stride, dtype=np.float32)
    v = np.arange(0, cam.height, stride, dtype=np.float32)
    return (u - np.float32(cam.cx)) / np.float32(cam.fx), (v - np.float32(cam.cy)) / np.float32(cam.fy)


def depth_to_points(depth: np.ndarray, cam: Pinhole, stride: int = 1, min_range: float = 0.0,
                    max_range: float = np.inf, depth_scale: float = 1.0) -> np.ndarray:
    """Organised cloud (H', W', 3) float32 in the optical frame (m) from a depth image.

    ``depth`` is float (m) or integer (``depth_scale`` m per unit: 0.001 for
    the drivers' 16UC1 millimetres, where 0 means no reading).  Pixels without
    a reading, or with depth outside [min_range, max_range], are NaN.
    ``stride`` >= 1 decimates rows and columns.
    """
    d = np.asarray(depth)
    if d.ndim != 2 or d.size == 0:
        raise CloudError(f"depth image must be 2-D and non-empty, got shape {d.shape}")
    if d.shape != (cam.height, cam.width):
        raise CloudError(f"depth image is {d.shape[1]} x {d.shape[0]} but camera_info says "
                         f"{cam.width} x {cam.height}")
    if int(stride) != stride or stride < 1:
        raise CloudError(f"stride must be an integer >= 1, got {stride}")
    z = d[::stride, ::stride].astype(np.float32) * np.float32(depth_scale)
    if np.issubdtype(d.dtype, np.integer):
        z[d[::stride, ::stride] == 0] = np.nan
    with np.errstate(invalid="ignore"):
        z[~((z >= min_range) & (z <= max_range))] = np.nan
    ux, vy = _unit_rays(cam, stride)
    out = np.empty(z.shape + (3,), np.float32)
    np.multiply(ux[None, :], z, out=out[..., 0])
    np.multiply(vy[:, None], z, out=out[..., 1])
    out[..., 2] = z
    return out


def transform_points(points: np.ndarray, rotation: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """``rotation @ p + translation`` for points (..., 3); returns (N, 3) float64 of the finite ones."""
    p = np.asarray(points, dtype=np.float64).reshape(-1, 3)
    p = p[np.isfinite(p).all(axis=1)]
    return p @ np.asarray(rotation, float).T + np.asarray(translation, float)
