"""Point clouds <-> sensor_msgs/PointCloud2 and CameraInfo helpers (message types, no rospy).

Packing is numpy structured arrays (one copy), not ``sensor_msgs.point_cloud2.create_cloud``,
which packs point by point in Python (~100x slower for 19 200 points); the
unit tests read our messages back with Debian's ``sensor_msgs.point_cloud2.read_points``
to prove the layout.  Layouts as the OpenNI/Astra drivers publish them:
``xyz`` = float32 x, y, z (12 bytes); ``xyzrgb`` = x, y, z + ``rgb`` float32
holding 0x00RRGGBB (PCL's packing, what RViz's RGB8 colour transformer reads).
"""
from __future__ import annotations

import numpy as np
from sensor_msgs.msg import CameraInfo, PointCloud2, PointField

from chefbot_vision.cloud import CloudError, Pinhole

_XYZ = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4")])
_XYZRGB = np.dtype([("x", "<f4"), ("y", "<f4"), ("z", "<f4"), ("rgb", "<u4")])


def _fields(names: tuple[str, ...]) -> list[PointField]:
    return [PointField(name=n, offset=4 * i, datatype=PointField.FLOAT32, count=1) for i, n in enumerate(names)]


def cloud_msg(points: np.ndarray, stamp, frame: str, rgb: np.ndarray | None = None) -> PointCloud2:
    """PointCloud2 of an organised (H, W, 3) float32 cloud (NaN = no point), optionally coloured by
    ``rgb`` (H, W, 3) uint8 in R, G, B order."""
    pts = np.asarray(points)
    if pts.ndim != 3 or pts.shape[2] != 3:
        raise CloudError(f"points must be (H, W, 3), got shape {pts.shape}")
    h, w = pts.shape[:2]
    dtype = _XYZ if rgb is None else _XYZRGB
    arr = np.empty((h, w), dtype)
    arr["x"], arr["y"], arr["z"] = pts[..., 0], pts[..., 1], pts[..., 2]
    if rgb is not None:
        c = np.asarray(rgb)
        if c.shape != (h, w, 3):
            raise CloudError(f"colours must be {(h, w, 3)} like the points, got {c.shape}")
        c = c.astype(np.uint32)
        arr["rgb"] = (c[..., 0] << 16) | (c[..., 1] << 8) | c[..., 2]
    m = PointCloud2()
    m.header.stamp, m.header.frame_id = stamp, frame
    m.height, m.width = h, w
    m.fields = _fields(("x", "y", "z") if rgb is None else ("x", "y", "z", "rgb"))
    m.is_bigendian, m.point_step, m.row_step = False, dtype.itemsize, dtype.itemsize * w
    m.is_dense = bool(np.isfinite(pts).all())
    m.data = arr.tobytes()
    return m


def cloud_xyz(msg: PointCloud2) -> np.ndarray:
    """(N, 3) float32 x, y, z of every point of a PointCloud2 (any float32 x/y/z layout), NaNs included."""
    offsets = {f.name: f for f in msg.fields}
    for n in ("x", "y", "z"):
        f = offsets.get(n)
        if f is None or f.datatype != PointField.FLOAT32:
            raise CloudError(f"point cloud has no float32 field '{n}' (fields: {', '.join(offsets) or 'none'})")
    n_pts = msg.width * msg.height
    if msg.is_bigendian:
        raise CloudError("big-endian point clouds are not supported")
    if msg.point_step < 12 or msg.row_step < msg.point_step * msg.width or len(msg.data) < msg.row_step * msg.height:
        raise CloudError(f"point cloud data is {len(msg.data)} bytes, too short for {msg.width} x {msg.height} "
                         f"points of {msg.point_step} bytes (row_step {msg.row_step})")
    if n_pts == 0:
        return np.zeros((0, 3), np.float32)
    dtype = np.dtype({"names": ["x", "y", "z"], "formats": ["<f4"] * 3,
                      "offsets": [offsets[n].offset for n in ("x", "y", "z")], "itemsize": msg.point_step})
    rows = np.frombuffer(msg.data, np.uint8, count=msg.row_step * msg.height).reshape(msg.height, msg.row_step)
    arr = np.ndarray((msg.height, msg.width), dtype, rows[:, :msg.point_step * msg.width].copy().data)
    return np.stack([arr["x"], arr["y"], arr["z"]], axis=-1).reshape(-1, 3)


def pinhole_from_info(info: CameraInfo) -> Pinhole:
    """Intrinsics of a CameraInfo (P when set, else K); CloudError when unusable."""
    return Pinhole.from_camera_info(info.width, info.height, list(info.K), list(info.P))


def camera_info(width: int, height: int, fx: float, fy: float, cx: float, cy: float, frame: str) -> CameraInfo:
    """A distortion-free CameraInfo (plumb_bob, D = 0) of a pinhole camera."""
    m = CameraInfo()
    m.header.frame_id = frame
    m.width, m.height = int(width), int(height)
    m.distortion_model = "plumb_bob"
    m.D = [0.0] * 5
    m.K = [fx, 0.0, cx, 0.0, fy, cy, 0.0, 0.0, 1.0]
    m.R = [1.0, 0.0, 0.0, 0.0, 1.0, 0.0, 0.0, 0.0, 1.0]
    m.P = [fx, 0.0, cx, 0.0, 0.0, fy, cy, 0.0, 0.0, 0.0, 1.0, 0.0]
    return m

