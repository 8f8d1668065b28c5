"""The simulated camera's point-cloud topics (ROS side; publishers passed in, no rospy import).

``camera/depth/points`` (XYZ, ``camera_depth_optical_frame``) from each published depth image,
and ``camera/depth_registered/points`` (XYZRGB, ``camera_rgb_optical_frame``) from each RGB
render's image + z-buffer -- the names and frames of the OpenNI/Astra drivers' launch files.
:meth:`CloudTopics.update` tells the simulator what to compute for whom is listening.
"""
from __future__ import annotations

from typing import Any

import numpy as np

from chefbot_sim.camera import registered_cloud
from chefbot_vision.cloud import depth_to_points
from chefbot_vision.ros_io import cloud_msg


class CloudTopics:
    """Owns the two cloud publishers; the sim node calls :meth:`update` with its subscription check
    and :meth:`on_depth` / :meth:`on_rgb` after publishing each image."""

    def __init__(self, sim: Any, pub_points: Any, pub_registered: Any) -> None:
        self.sim, self.pub_points, self.pub_registered = sim, pub_points, pub_registered
        cam = sim.params.depth_camera
        self.depth_frame, self.rgb_frame = cam.depth_frame, cam.rgb_frame
        self.cutoff = cam.point_cloud_cutoff
        self.want_points = self.want_registered = False

    def update(self) -> tuple[bool, bool]:
        """(depth wanted, rgb wanted) by the clouds' subscribers; switches the sim to dense depth
        while camera/depth/points has any."""
        self.want_points = self.pub_points.get_num_connections() > 0
        self.want_registered = self.pub_registered.get_num_connections() > 0
        self.sim.dense_depth = self.want_points
        return self.want_points, self.want_registered

    def on_depth(self, depth: np.ndarray, stamp: Any) -> None:
        """A new depth image (m): publish its point cloud if someone listens."""
        if self.want_points:
            pts = depth_to_points(depth, self.sim.depth_camera, min_range=self.cutoff)
            self.pub_points.publish(cloud_msg(pts, stamp, self.depth_frame))

    def on_rgb(self, stamp: Any) -> None:
        """A new colour image: publish the registered (coloured) cloud if someone listens."""
        frame = self.sim.last_rgb
        if self.want_registered and frame is not None:
            stride = self.sim.options.registered_stride
            pts, colours = registered_cloud(frame, self.sim.rgb_camera, stride)
            self.pub_registered.publish(cloud_msg(pts, stamp, self.rgb_frame, colours))
