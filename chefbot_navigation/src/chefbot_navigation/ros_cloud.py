"""move_base's point-cloud obstacle source (ROS glue: rospy, tf2): subscription, tf, one update call.

Reads ``~pointcloud_layer/<name>`` (:class:`chefbot_navigation.pointcloud_layer.CloudLayerParams`),
subscribes the cloud topic when ``enabled``, transforms each cloud into the global frame with tf2
(full 3-D: the camera's height and tilt matter) and feeds the :class:`PointCloudLayer` attached
to the current :class:`LayeredCostmap` (a new map gets a new layer).  Bad clouds and missing tf
are logged (throttled) and skipped.
"""
from __future__ import annotations

import threading
import time
from collections.abc import Callable

import numpy as np
import rospy
from sensor_msgs.msg import PointCloud2
from tf.transformations import quaternion_matrix

from chefbot_common.params import private_spec
from chefbot_navigation.costmap import LayeredCostmap
from chefbot_navigation.pointcloud_layer import CloudLayerParams, PointCloudLayer
from chefbot_navigation.ros_util import TF_ERRORS
from chefbot_vision.cloud import CloudError, transform_points
from chefbot_vision.ros_io import cloud_xyz

CLOUD = private_spec(CloudLayerParams, "pointcloud_layer/")   # move_base's ~pointcloud_layer/<name> params


class CloudInput:
    """The subscription and the update call; ``layers()`` returns move_base's current costmap layers."""

    def __init__(self, tf_buffer, global_frame: str, lock: threading.RLock,
                 layers: Callable[[], LayeredCostmap | None]) -> None:
        self.params = CLOUD.read(rospy.get_param)
        self.buffer, self.global_frame, self.lock, self.layers = tf_buffer, global_frame, lock, layers
        self.last_cost = 0.0   # s of CPU per cloud (the latest), for logs and the bench
        if self.params.enabled:
            rospy.Subscriber(self.params.topic, PointCloud2, self.on_cloud, queue_size=1, buff_size=2 ** 24)
            rospy.loginfo("move_base: point-cloud obstacles from %s, heights %.2f..%.2f m",
                          rospy.resolve_name(self.params.topic), self.params.min_obstacle_height,
                          self.params.max_obstacle_height)

    def on_cloud(self, msg: PointCloud2) -> None:
        t0 = time.process_time()
        p = self.params
        try:
            pts = cloud_xyz(msg)
        except CloudError as exc:
            rospy.logerr_throttle(5.0, f"move_base: point cloud from {msg.header.frame_id!r} ignored: {exc}")
            return
        if msg.height > 1 and p.decimation > 1:
            pts = pts.reshape(msg.height, msg.width, 3)[::p.decimation, ::p.decimation].reshape(-1, 3)
        try:
            tf = self.buffer.lookup_transform(self.global_frame, msg.header.frame_id, msg.header.stamp,
                                              rospy.Duration(p.transform_tolerance))
        except TF_ERRORS as exc:
            rospy.logwarn_throttle(5.0, f"move_base: point cloud dropped: no transform {self.global_frame} -> "
                                        f"{msg.header.frame_id}: {exc}")
            return
        q, tr = tf.transform.rotation, tf.transform.translation
        origin = np.array([tr.x, tr.y, tr.z])
        rot = quaternion_matrix((q.x, q.y, q.z, q.w))[:3, :3]
        pts = transform_points(pts, rot, origin)
        with self.lock:
            layers = self.layers()
            if layers is None:
                return
            if layers.cloud_layer is None:
                layers.cloud_layer = PointCloudLayer(layers.info, p)
            layers.cloud_layer.update(pts, origin)
            layers.layers_changed()
        self.last_cost = time.process_time() - t0
