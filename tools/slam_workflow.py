"""The book's ch. 4 hand-over, map -> save -> localize, on a running ``gmapping_demo.launch explore:=true``.

Shared by ``make demo SLAM=1`` (tools/slam_demo.py) and the slam_workflow rostests
(tests/test/slam_workflow.test and tests/test/slam_workflow_hotel.test):

1. :class:`ExploreWatch` waits for ``explore/done`` (latched Bool) and hands each of
   explore's progress lines (from ``/rosout``) to a callback;
2. :func:`save_map` runs our ``map_saver`` and reads the files back;
3. :func:`slam_pose` is SLAM's last ``map -> base_footprint`` (amcl's initial pose:
   the saved map's frame is SLAM's map frame);
4. :func:`stop_mapping` kills ``slam`` and ``explore`` and waits until they are gone;
5. :func:`localization_commands`: our ``map_server`` on the saved file and our ``amcl``
   started at that pose (``move_base`` keeps running and takes the served map);
   :func:`wait_localized` waits for amcl, :func:`clear_costmaps` drops the scan obstacles
   marked while mapping;
6. :func:`judge_map` (test oracle: reads the world raster): map quality and the saved
   map's pose in the world (``map_align.align_maps``, align_tables' registration);
7. :class:`SlamTrack` (test oracle: reads ``ground_truth/odom``) records SLAM's live pose
   next to the truth while mapping, for the trajectory error of the run.
8. :class:`NodeLog` keeps a node's own log lines (explore's progress, slam's loop closures),
   :func:`slam_events_summary` sums up the latter in one line for a failure message.

Needs rospy initialised on the launch's master; wall-clock timeouts throughout (the
sim may run slower or faster than real time).
"""
from __future__ import annotations

import re
import subprocess
import threading
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import rosnode
import rospy
import tf2_ros
from delivery import TruthHistory, latest_pose
from nav_msgs.msg import Odometry
from rosgraph_msgs.msg import Log
from std_msgs.msg import Bool

from chefbot_common.geometry import Pose2D, yaw_from_quaternion
from chefbot_common.grid import OccupancyMap
from chefbot_common.map_io import load_map
from chefbot_navigation.slam.mapper import (
    EVENT_CLOSURE,
    EVENT_CORRECTION,
    EVENT_DROPPED,
    EVENT_IMU,
    EVENT_OUTLIER,
    IMU_REJECTED,
)
from chefbot_navigation.slam.metrics import ate_rms

ROOT = Path(__file__).resolve().parent.parent
NAV_LAUNCH = ROOT / "chefbot_navigation" / "launch"


class WorkflowError(RuntimeError):
    """A stage of the workflow failed; the message says which and why."""


class NodeLog:
    """A node's own log lines (those starting with ``prefix``) from ``/rosout``, as they come.

    ``/rosout``, which every node publishes itself, not ``/rosout_agg``: the latter needs the rosout node,
    which rostest's master does not start (under rostest it stayed silent, and the workflow test's summary
    read "0 loop closures" whatever slam had logged)."""

    def __init__(self, node: str, prefix: str) -> None:
        self.node, self.prefix = node, prefix
        self.lines: list[str] = []
        self._lock = threading.Lock()
        self._sub = rospy.Subscriber("/rosout", Log, self._on_log, queue_size=100)

    def _on_log(self, msg: Log) -> None:
        if msg.name == self.node and msg.msg.startswith(self.prefix):
            with self._lock:
                self.lines.append(msg.msg)

    def since(self, shown: int) -> tuple[list[str], int]:
        """The lines after the first ``shown``, and the count so far."""
        with self._lock:
            return self.lines[shown:], len(self.lines)

    def close(self) -> None:
        self._sub.unregister()


class ExploreWatch:
    """Follows the ``explore`` node: its log lines (``explore: ...``) and its latched ``explore/done``."""

    def __init__(self, node: str = "/explore") -> None:
        self.node = node
        self.done: bool | None = None
        self.log = NodeLog(node, "explore:")
        self._sub = rospy.Subscriber(f"{node}/done", Bool, self._on_done, queue_size=1)

    def _on_done(self, msg: Bool) -> None:
        self.done = bool(msg.data)

    def wait(self, timeout_wall: float, alive: Callable[[], bool] = lambda: True,
             echo: Callable[[str], None] | None = None) -> bool:
        """Wait for ``explore/done``; echo each new log line; True = the map is complete.

        Raises WorkflowError when the wall-clock timeout runs out or ``alive()`` turns false."""
        deadline, shown, next_check = time.monotonic() + timeout_wall, 0, 0.0
        while self.done is None:
            new, shown = self.log.since(shown)
            for line in new if echo else []:
                echo(line)
            if not alive():
                raise WorkflowError("the simulation / SLAM launch stopped during exploration")
            if shown and time.monotonic() > next_check:       # explore is up: it and slam must stay up
                next_check = time.monotonic() + 5.0
                gone = [n for n in ("/slam", self.node) if n not in rosnode.get_node_names()]
                if gone and self.done is None:
                    raise WorkflowError(f"{', '.join(gone)} exited during exploration (explore/done never came)")
            if time.monotonic() > deadline or rospy.is_shutdown():
                raise WorkflowError(f"exploration did not end within {timeout_wall:.0f} s wall time")
            time.sleep(0.2)
        time.sleep(0.5)                 # explore logs its final line just before publishing done
        new, _ = self.log.since(shown)
        for line in new if echo else []:
            echo(line)
        return self.done

    def final_line(self) -> str:
        """explore's ``explore: finished (...)`` line, or "" when none came."""
        lines, _ = self.log.since(0)
        return next((ln for ln in reversed(lines) if ln.startswith("explore: finished")), "")

    def close(self) -> None:
        self._sub.unregister()
        self.log.close()


class SlamTrack:
    """SLAM's live ``map -> base_footprint`` next to the simulator's truth (TEST ORACLE: judging only).

    Every ``period`` s (sim) the latest tf estimate is paired with ``ground_truth/odom`` interpolated at
    the estimate's own stamp.  The estimate is what move_base navigated on at that moment, before later
    loop closures corrected the past: :meth:`report` gives its error against the truth in the frame the
    saved map was registered to (the robot's live localization error) and the ATE after the best rigid
    fit (the issue's metric, comparable with bench_slam's offline figure)."""

    def __init__(self, period: float = 0.5, map_frame: str = "map", base_frame: str = "base_footprint") -> None:
        self.frames = (map_frame, base_frame)
        self._lock = threading.Lock()
        self._history = TruthHistory(200)                                              # 4 s at 50 Hz
        self.samples: list[tuple[float, Pose2D, Pose2D]] = []                          # t, estimate, truth (world)
        self.buffer = tf2_ros.Buffer()
        self._listener = tf2_ros.TransformListener(self.buffer)
        self._sub = rospy.Subscriber("ground_truth/odom", Odometry, self._history.add, queue_size=50)
        self._timer = rospy.Timer(rospy.Duration(period), self._sample)

    def _sample(self, _event) -> None:
        stamped = latest_pose(self.buffer, *self.frames)
        if stamped is None:
            return                      # SLAM not up yet
        t, estimate = stamped
        truth = self._history.at(t)
        with self._lock:
            if truth is None or (self.samples and t <= self.samples[-1][0]):
                return                  # no truth at that stamp, or nothing new (a stale tf)
            self.samples.append((t, estimate, Pose2D(*truth)))

    def close(self) -> None:
        self._timer.shutdown()
        self._sub.unregister()

    def report(self, map_in_world: Pose2D) -> dict:
        """:func:`track_figures` of the samples so far."""
        with self._lock:
            samples = list(self.samples)
        return track_figures(samples, map_in_world)


def track_figures(samples: list[tuple[float, Pose2D, Pose2D]], map_in_world: Pose2D) -> dict:
    """Live error figures (m, deg, s since the first sample) of ``samples`` (t, SLAM's estimate in its map
    frame, truth in the world) with the saved map registered at ``map_in_world``; JSON-ready, with the
    samples (t, estimate and truth in the map frame) for plots and post-mortems."""
    if len(samples) < 2:
        return {"track_samples": len(samples)}
    to_map = map_in_world.inverse()
    t = np.array([s[0] for s in samples])
    est = np.array([[s[1].x, s[1].y, s[1].yaw] for s in samples])
    truth = np.array([[h.x, h.y, h.yaw] for h in (to_map.compose(s[2]) for s in samples)])
    err = np.hypot(*(est[:, :2] - truth[:, :2]).T)
    yaw_err = np.degrees(np.abs(np.remainder(est[:, 2] - truth[:, 2] + np.pi, 2 * np.pi) - np.pi))
    k = int(np.argmax(err))
    return {"track_samples": len(samples), "live_error_rms_m": float(np.sqrt(np.mean(err ** 2))),
            "live_error_max_m": float(err[k]), "live_error_max_at_s": float(t[k] - t[0]),
            "live_yaw_error_max_deg": float(yaw_err.max()),
            "live_ate_rms_m": ate_rms(est[:, :2], truth[:, :2]),
            "track": {"t": np.round(t - t[0], 2).tolist(), "estimate": np.round(est, 4).tolist(),
                      "truth": np.round(truth, 4).tolist()}}


_CLOSURE = re.compile(rf"{EVENT_CLOSURE} \d+ -> \d+: corrected ([\d.]+) m, ([\d.]+) deg \(([^)]*)\)")


def slam_events_summary(lines: list[str]) -> str:
    """One line on the slam node's events (its ``slam: ...`` log lines): how many loop closures and the
    largest, dropped loop matches, large scan-matcher corrections, IMU rejections and scan-loss warnings.
    Lines are counted by the mapper's own event prefixes; a closure whose figures do not parse is still
    counted."""
    found = [ln for ln in lines if EVENT_CLOSURE in ln]
    closures = [(float(m[1]), float(m[2]), m[3]) for m in map(_CLOSURE.search, found) if m]
    parts = [f"{len(found)} loop closure{'s' * (len(found) != 1)}"]
    if closures:
        d, a, how = max(closures)
        parts[0] += f" (largest {d:.3f} m / {a:.1f} deg: {how})"
    if len(closures) < len(found):
        parts.append(f"{len(found) - len(closures)} closure line(s) not understood: {found[0][:160]}")
    for what, key in (("loop match(es) dropped", EVENT_DROPPED), ("large correction(s)", EVENT_CORRECTION),
                      ("loop edge(s) down-weighted", EVENT_OUTLIER),
                      ("IMU rejection(s)", f"{EVENT_IMU} {IMU_REJECTED}"),
                      ("scan-loss warning(s)", "falling behind")):
        n = sum(key in ln for ln in lines)
        if n:
            parts.append(f"{n} {what}")
    return "slam: " + ", ".join(parts)


def save_map(prefix: Path, env: dict | None = None, timeout: float = 120.0) -> OccupancyMap:
    """``map_saver -f prefix`` on the current master; the saved map read back from ``prefix.yaml``."""
    prefix.parent.mkdir(parents=True, exist_ok=True)
    try:
        r = subprocess.run(["rosrun", "chefbot_navigation", "map_saver", "-f", str(prefix)], env=env,
                           capture_output=True, text=True, timeout=timeout)
    except subprocess.TimeoutExpired as exc:
        raise WorkflowError(f"map_saver wrote nothing within {timeout:.0f} s") from exc
    yaml = prefix.with_suffix(".yaml")
    if r.returncode != 0 or not yaml.is_file():
        raise WorkflowError(f"map_saver failed (exit {r.returncode}): {(r.stderr or r.stdout).strip()[-500:]}")
    return load_map(yaml)


def slam_pose(buffer: tf2_ros.Buffer, timeout: float = 10.0, map_frame: str = "map",
              base_frame: str = "base_footprint") -> Pose2D:
    """SLAM's latest ``map -> base_footprint`` (m, rad)."""
    try:
        t = buffer.lookup_transform(map_frame, base_frame, rospy.Time(0), rospy.Duration(timeout)).transform
    except (tf2_ros.LookupException, tf2_ros.ConnectivityException, tf2_ros.ExtrapolationException) as exc:
        raise WorkflowError(f"no tf {map_frame} -> {base_frame} from SLAM: {exc}") from exc
    q = t.rotation
    return Pose2D(t.translation.x, t.translation.y, yaw_from_quaternion(q.x, q.y, q.z, q.w))


def stop_mapping(nodes: tuple[str, ...] = ("/slam", "/explore"), timeout: float = 30.0) -> None:
    """Kill the mapping nodes and wait (wall clock) until none of them is registered any more."""
    running = [n for n in nodes if n in rosnode.get_node_names()]
    if running:
        rosnode.kill_nodes(running)
    deadline = time.monotonic() + timeout
    while any(n in rosnode.get_node_names() for n in nodes):
        if time.monotonic() > deadline:
            raise WorkflowError(f"{', '.join(nodes)} still running {timeout:.0f} s after rosnode kill")
        time.sleep(0.2)


def localization_commands(map_yaml: Path, start: Pose2D, cov: float = 0.01) -> list[list[str]]:
    """roslaunch commands: our map_server on ``map_yaml``, our amcl started at ``start`` (map frame) with
    variance ``cov`` (m^2 and rad^2; SLAM's pose is good to a few cm)."""
    return [["roslaunch", str(NAV_LAUNCH / "map_server.launch"), f"map_file:={map_yaml}"],
            ["roslaunch", str(NAV_LAUNCH / "includes" / "amcl.launch.xml"), f"initial_pose_x:={start.x}",
             f"initial_pose_y:={start.y}", f"initial_pose_a:={start.yaw}", f"initial_cov_xx:={cov}",
             f"initial_cov_yy:={cov}", f"initial_cov_aa:={cov}"]]


def wait_localized(alive: Callable[[], bool], timeout: float = 60.0) -> Pose2D:
    """Wait (wall clock) for amcl's first ``amcl_pose`` (latched) on the saved map; its pose (map frame).
    (tf alone cannot tell: SLAM's last future-dated map -> odom stays in a tf buffer for a while.)"""
    from geometry_msgs.msg import PoseWithCovarianceStamped

    got: list = []
    sub = rospy.Subscriber("amcl_pose", PoseWithCovarianceStamped, got.append, queue_size=1)
    deadline = time.monotonic() + timeout
    try:
        while not got:
            if not alive():
                raise WorkflowError("map_server or amcl stopped")
            if time.monotonic() > deadline or rospy.is_shutdown():
                raise WorkflowError(f"amcl published no amcl_pose within {timeout:.0f} s")
            time.sleep(0.1)
    finally:
        sub.unregister()
    p = got[0].pose.pose
    return Pose2D(p.position.x, p.position.y, yaw_from_quaternion(*(getattr(p.orientation, k) for k in "xyzw")))


def in_world(saved: OccupancyMap, truth: OccupancyMap, map_in_world: Pose2D) -> OccupancyMap:
    """The saved map resampled onto the world raster's grid through ``map_in_world`` (nearest cell; -1 outside)."""
    import numpy as np

    ti = truth.info
    rows, cols = np.mgrid[0:ti.height, 0:ti.width]
    wx, wy = ti.cell_to_world(rows, cols)
    inv = map_in_world.inverse()
    c, s = np.cos(inv.yaw), np.sin(inv.yaw)
    r, k = saved.info.world_to_cell(inv.x + c * wx - s * wy, inv.y + s * wx + c * wy)
    ok = saved.info.inside(r, k)
    data = np.full((ti.height, ti.width), -1, dtype=np.int8)
    data[ok] = saved.data[r[ok], k[ok]]
    return OccupancyMap(ti, data)


def clear_costmaps(timeout: float = 10.0) -> None:
    """``move_base/clear_costmaps``: forget the obstacles the scans marked while mapping (any phantom among
    them), so the saved map alone is what the deliveries start from."""
    from std_srvs.srv import Empty

    try:
        rospy.wait_for_service("move_base/clear_costmaps", timeout=timeout)
        rospy.ServiceProxy("move_base/clear_costmaps", Empty)()
    except (rospy.ROSException, rospy.ServiceException) as exc:
        raise WorkflowError(f"move_base/clear_costmaps failed: {exc}") from exc


def judge_map(saved: OccupancyMap, truth: OccupancyMap, start_xy: tuple[float, float]) -> tuple:
    """(MapQuality, Alignment) of the saved map against the world raster (TEST ORACLE).  The saved map's frame
    in the world (``alignment.pose``: map_in_world) comes from align_tables' registration; quality is
    slam/metrics.map_quality of the saved map carried into the world through it (a SLAM map's frame is the
    odometry frame at the first scan: a rotated but good map is not penalised), ``start_xy``: the robot's start
    in the world (m)."""
    from chefbot_navigation.map_align import align_maps
    from chefbot_navigation.slam.metrics import map_quality

    align = align_maps(truth, saved, source_name="world raster", target_name="saved SLAM map")
    return map_quality(in_world(saved, truth, align.pose), truth, start_xy, search=1), align
