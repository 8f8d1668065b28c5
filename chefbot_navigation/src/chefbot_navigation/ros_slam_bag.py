"""Offline SLAM over a rosbag (``scan`` + ``tf``/``tf_static``; ``imu/data`` and ``bumper`` when recorded),
as fast as the machine allows.

Used by ``nodes/slam_offline`` and the benchmark.  All tf messages are loaded
into one tf2 ``BufferCore`` whose cache spans the whole bag, then the scans
are fed in stamp order to the same :class:`~chefbot_navigation.slam_io.SlamFrontend`
the live node uses, so the offline map reproduces the live one; then the core's final
refinement passes (``refine_passes``, :meth:`~chefbot_navigation.slam.mapper.Slam.refine`) run.
"""
from __future__ import annotations

import sys
import time
import warnings
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import genpy
import rosbag
import tf2_py

from chefbot_common.geometry import Pose2D
from chefbot_navigation.slam.mapper import SlamConfig
from chefbot_navigation.slam_io import SlamFrontend, SlamInputError


class BagError(RuntimeError):
    """The bag cannot be mapped (missing, unreadable, no scan topic); the message says why."""


@dataclass
class OfflineResult:
    """The front end (map + trajectory inside), how many scans were used / skipped (an error) /
    left out by ``scan_filter`` (``decimated``), and timing."""

    front: SlamFrontend
    scans: int
    skipped: int
    bag_seconds: float
    wall_seconds: float
    first_error: str = ""
    decimated: int = 0

    @property
    def speedup(self) -> float:
        """Bag time / processing time (x real time)."""
        return self.bag_seconds / max(self.wall_seconds, 1e-9)


def _topic(name: str) -> str:
    return name if name.startswith("/") else "/" + name


def progress_bar(done: int, total: int, t0: float, bag_t: float, width: int = 30) -> None:
    """One-line progress on stderr: bar, percentage, scans, speed (x real time)."""
    frac = done / max(total, 1)
    rate = bag_t / max(time.monotonic() - t0, 1e-9)
    bar = "#" * int(frac * width) + "-" * (width - int(frac * width))
    sys.stderr.write(f"\r[{bar}] {100 * frac:5.1f} % {done}/{total} scans, {rate:5.1f}x real time")
    if done >= total:
        sys.stderr.write("\n")
    sys.stderr.flush()


def run_bag(bag_path: str | Path, cfg: SlamConfig, scan_topic: str = "scan", base_frame: str = "base_footprint",
            odom_frame: str = "odom", progress: Callable[[int, int, float, float], None] | None = None,
            odom_filter: Callable[[float, Pose2D], Pose2D] | None = None,
            scan_filter: Callable[[float, Pose2D], bool] | None = None, imu_topic: str = "imu/data",
            bumper_topic: str = "bumper") -> OfflineResult:
    """Map a bag; raises :class:`BagError` for a missing/unreadable bag or one without the scan topic.

    ``imu_topic`` (sensor_msgs/Imu) and ``bumper_topic`` (std_msgs/Bool) go to the front end in the
    bag's order among the scans, as the live node gets them, when the bag has them ("": not used).

    Tests / benchmark only:

    * ``odom_filter(t, pose)`` may replace each odometry pose, e.g. to inject
      wheel noise into a bag recorded with perfect odometry.  It is called once
      per scan given to the SLAM, in stamp order (never for a scan that
      ``scan_filter`` rejected), so a stateful filter sees one stream.
    * ``scan_filter(t, pose)`` is asked first for each scan with the *recorded*
      odometry pose (before ``odom_filter``: in the simulator's bags that is
      nearly the true motion, so a decimation by distance keeps the same scans
      whatever error ``odom_filter`` adds); a scan it rejects is left out
      entirely (``OfflineResult.decimated``, not ``scans`` nor ``skipped``).  A
      scan whose odometry cannot be looked up goes on to fail as usual.
    """
    path = Path(bag_path)
    if not path.is_file():
        raise BagError(f"{path}: no such bag file")
    try:
        bag = rosbag.Bag(str(path))
    except Exception as exc:  # rosbag raises ROSBagException, OSError, ...
        raise BagError(f"{path}: cannot read bag ({exc})") from exc
    with bag:
        info = bag.get_type_and_topic_info().topics
        scan_t = _topic(scan_topic)
        if scan_t not in info:
            raise BagError(f"{path}: bag has no topic '{scan_t}' (topics: {', '.join(sorted(info)) or 'none'})")
        if info[scan_t].msg_type != "sensor_msgs/LaserScan":
            raise BagError(f"{path}: topic '{scan_t}' is {info[scan_t].msg_type}, not sensor_msgs/LaserScan")
        total = info[scan_t].message_count
        aux = {}
        for name, kind in ((imu_topic, "sensor_msgs/Imu"), (bumper_topic, "std_msgs/Bool")):
            if name and _topic(name) in info:
                if info[_topic(name)].msg_type != kind:
                    raise BagError(f"{path}: topic '{_topic(name)}' is {info[_topic(name)].msg_type}, not {kind}")
                aux[_topic(name)] = kind
        start, end = bag.get_start_time(), bag.get_end_time()
        core = tf2_py.BufferCore(genpy.Duration(max(end - start, 0.0) + 60.0))
        with warnings.catch_warnings():
            # bag messages are rosbag's own generated classes; tf2 warns about their type names
            warnings.simplefilter("ignore", UserWarning)
            for topic, msg, _ in bag.read_messages(topics=["/tf", "/tf_static"]):
                for tr in msg.transforms:
                    if tr.child_frame_id.lstrip("/") == odom_frame.lstrip("/") and \
                            tr.header.frame_id.lstrip("/") != base_frame.lstrip("/"):
                        continue    # a recorded map->odom (from a live SLAM/AMCL run) is not an input
                    if topic == "/tf_static":
                        core.set_transform_static(tr, "bag")
                    else:
                        core.set_transform(tr, "bag")

        def lookup(target: str, source: str, stamp):
            return core.lookup_transform_core(target, source, stamp)

        front = SlamFrontend(cfg, lookup, base_frame, odom_frame)
        raw = front.odom_pose
        if odom_filter is not None:
            front.odom_pose = lambda stamp: odom_filter(stamp.to_sec(), raw(stamp))  # type: ignore[method-assign]
        t0 = time.monotonic()
        done = skipped = decimated = 0
        first_error = ""
        first_t = last_t = None
        for topic, msg, _ in bag.read_messages(topics=[scan_t, *aux]):
            if topic != scan_t:
                if aux[topic] == "sensor_msgs/Imu":
                    front.add_imu(msg)
                else:
                    front.add_bumper(msg.data)
                continue
            st = msg.header.stamp.to_sec()
            first_t = st if first_t is None else first_t
            last_t = st
            if scan_filter is not None and not _keep(scan_filter, st, raw, msg.header.stamp):
                decimated += 1
            else:
                try:
                    front.process(msg)
                except SlamInputError as exc:
                    skipped += 1
                    first_error = first_error or str(exc)
                done += 1
            seen = done + decimated
            if progress is not None and (seen % 50 == 0 or seen == total):
                progress(seen, total, t0, st - first_t)
        if done > skipped:
            front.slam.refine()     # cfg.refine_passes final passes (0: none)
        wall = time.monotonic() - t0
    if done == skipped:
        raise BagError(f"{path}: no usable scan on '{scan_t}' ({skipped} skipped; first error: {first_error})")
    return OfflineResult(front, done - skipped, skipped, (last_t or 0.0) - (first_t or 0.0), wall, first_error,
                         decimated)


def _keep(scan_filter: Callable[[float, Pose2D], bool], t: float, odom_pose: Callable[[object], Pose2D],
          stamp) -> bool:
    """``scan_filter``'s verdict on the scan at ``t`` given the recorded odometry; a scan without odometry is
    kept (the front end then reports it as skipped, with the reason)."""
    try:
        pose = odom_pose(stamp)
    except SlamInputError:
        return True
    return bool(scan_filter(t, pose))
