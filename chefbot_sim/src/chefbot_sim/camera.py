"""The simulated RGB-D camera's rendered images and point clouds (no pybullet import, no rospy).

Costs decide the split (measured; figures in docs/benchmarks.md, sim rows):

* RGB: TinyRenderer through the facade (:meth:`chefbot_sim.bullet.BulletSim.render`)
  at ``rgb_width`` x ``rgb_height`` (320 x 240), only while someone subscribes;
  the same render's z-buffer is the depth *registered to the RGB camera*, so
  ``camera/depth_registered/points`` (XYZRGB in ``camera_rgb_optical_frame``,
  as the OpenNI/Astra drivers publish it) costs no second render.
* depth image: the ray caster (band rows exact, the rest coarse: cheap, what
  ``depth_to_scan`` needs) -- unless ``camera/depth/points`` is subscribed:
  a cloud needs every pixel, so then the depth camera is rendered in full
  (160 x 120 TinyRenderer, cheaper than casting all 19 200 rays).
* clouds: :func:`chefbot_vision.cloud.depth_to_points` (pinhole model, numpy).
"""
from __future__ import annotations

from dataclasses import dataclass
from typing import Protocol

import numpy as np

from chefbot_vision.cloud import Pinhole, depth_to_points

NEAR_PLANE = 0.05  # m: TinyRenderer's near clip; nearer than any valid reading (min_range 0.45 m)


class Renderer(Protocol):
    """What the camera needs of the facade (chefbot_sim.bullet.BulletSim)."""

    def frame_pose(self, name: str) -> tuple[np.ndarray, np.ndarray]:
        """World position and 3 x 3 rotation of link frame ``name``."""

    def render(self, width: int, height: int, eye: np.ndarray, rotation: np.ndarray, fy: float, near: float,
               far: float, rgb: bool) -> tuple[np.ndarray | None, np.ndarray]:
        """Render an (RGB or None, depth m) image pair from a camera pose."""


@dataclass
class RgbFrame:
    """One RGB render: image (H, W, 3) uint8 RGB and its z-buffer depth (H, W) float32 m (NaN = nothing)."""

    image: np.ndarray
    depth: np.ndarray


class RgbdRenderer:
    """Renders the RGB camera and (for clouds) the full depth camera from their optical frames."""

    def __init__(self, bullet: Renderer, rgb: Pinhole, depth: Pinhole, rgb_frame: str, depth_frame: str,
                 min_range: float, max_range: float) -> None:
        self.bullet, self.rgb, self.depth = bullet, rgb, depth
        self.rgb_frame, self.depth_frame = rgb_frame, depth_frame
        self.min_range, self.max_range = float(min_range), float(max_range)

    def _valid(self, depth: np.ndarray) -> np.ndarray:
        d = depth.astype(np.float32)
        d[~((d >= self.min_range) & (d <= self.max_range))] = np.nan
        return d

    def render_rgb(self) -> RgbFrame:
        """The RGB image and the depth registered to it (readings outside min..max range are NaN)."""
        pos, rot = self.bullet.frame_pose(self.rgb_frame)
        img, depth = self.bullet.render(self.rgb.width, self.rgb.height, pos, rot, self.rgb.fy, NEAR_PLANE,
                                        self.max_range, rgb=True)
        return RgbFrame(img, self._valid(depth))

    def render_depth(self) -> np.ndarray:
        """Every pixel of the depth camera (m along the optical axis, float32; +inf = nothing within
        max_range, the ray caster's convention before noise and range checks)."""
        pos, rot = self.bullet.frame_pose(self.depth_frame)
        _, depth = self.bullet.render(self.depth.width, self.depth.height, pos, rot, self.depth.fy, NEAR_PLANE,
                                      self.max_range, rgb=False)
        return depth.astype(np.float32)


def registered_cloud(frame: RgbFrame, cam: Pinhole, stride: int) -> tuple[np.ndarray, np.ndarray]:
    """Organised XYZ (H', W', 3) in the RGB optical frame and its colours (H', W', 3), every ``stride``-th pixel."""
    pts = depth_to_points(frame.depth, cam, stride)
    return pts, frame.image[::stride, ::stride]
