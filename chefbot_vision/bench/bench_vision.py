"""Benchmark: the simulated RGB-D camera and the point-cloud obstacle layer (hotel world).

    python chefbot_vision/bench/bench_vision.py [--quick]

Rows (ms are medians of wall time per call, on whatever load the machine has):
* camera frames: RGB 320 x 240 (TinyRenderer), depth by ray casting (band + coarse),
  depth rendered in full (what camera/depth/points needs), depth -> XYZ cloud + PointCloud2,
  registered XYZRGB cloud + PointCloud2;
* the point-cloud obstacle layer: one cloud of the simulated camera into the hotel map's
  voxel columns (the move_base cost per cloud; decimation 2 as in move_base.yaml);
* the sim core (no ROS) with every camera output at 10 Hz, as a multiple of real time;
* through ROS (not with --quick): navigation_demo.launch (sim + map server + fake localization +
  move_base with the cloud layer) at real_time_factor 1 with RViz-like subscribers on every camera
  topic, and the same uncapped (real_time_factor 0): sim seconds per wall second over 20 s.
"""
from __future__ import annotations

import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[2]
CAMERA_TOPICS = ["camera/rgb/image_raw", "camera/rgb/camera_info", "camera/depth/image_raw",
                 "camera/depth/camera_info", "camera/depth/points", "camera/depth_registered/points", "scan"]


def _median_ms(fn, n: int) -> float:
    ts = []
    for _ in range(n):
        t0 = time.perf_counter()
        fn()
        ts.append(time.perf_counter() - t0)
    return float(np.median(ts) * 1e3)


def _row(case: str, metric: str, ours: float, goal: str | None, met: bool | None) -> dict:
    return {"bench": "vision", "case": case, "metric": metric, "ours": round(ours, 3), "reference": None,
            "reference_name": None, "goal": goal, "met": met}


def _registered_msg(frame, cam):
    from chefbot_sim.camera import registered_cloud
    from chefbot_vision.ros_io import cloud_msg

    pts, colours = registered_cloud(frame, cam, 2)
    return cloud_msg(pts, None, "f", colours)


def run(quick: bool = False) -> list[dict]:
    from chefbot_common.geometry import Pose2D
    from chefbot_common.map_io import load_map
    from chefbot_description.model import expand_xacro
    from chefbot_navigation.pointcloud_layer import CloudLayerParams, PointCloudLayer
    from chefbot_sim.sim import SimOptions, Simulator
    from chefbot_sim.world import load_world
    from chefbot_vision.cloud import depth_to_points, transform_points
    from chefbot_vision.ros_io import cloud_msg

    n = 5 if quick else 20
    rows = []
    sim = Simulator(expand_xacro(), load_world(ROOT / "chefbot_sim" / "worlds" / "hotel.yaml"),
                    Pose2D(1.0, -1.5, -0.3), SimOptions(seed=1))
    try:
        sim.run(0.3)
        rgb_ms = _median_ms(sim.rgb_image, n)
        rows.append(_row("camera: RGB 320x240 frame (TinyRenderer)", "ms/frame", rgb_ms,
                         "<= 50 ms (10 Hz in half a core)", rgb_ms <= 50))
        rows.append(_row("camera: depth 160x120 by ray casting (band exact + coarse)", "ms/frame",
                         _median_ms(sim.depth_image, n), None, None))
        sim.dense_depth = True
        rows.append(_row("camera: depth 160x120 rendered in full (while camera/depth/points is subscribed)",
                         "ms/frame", _median_ms(sim.depth_image, n), None, None))
        depth = sim.depth_image()
        cam = sim.depth_camera
        rows.append(_row("camera: depth -> XYZ cloud + PointCloud2 (19 200 points)", "ms/frame",
                         _median_ms(lambda: cloud_msg(depth_to_points(depth, cam), None, "f"), n), None, None))
        frame, rcam = sim.last_rgb, sim.rgb_camera
        rows.append(_row("camera: registered XYZRGB cloud + PointCloud2 (stride 2: 19 200 points)", "ms/frame",
                         _median_ms(lambda: _registered_msg(frame, rcam), n), None, None))
        # the layer: the camera's cloud into the hotel map (as move_base does it, decimation 2)
        pos, rot = sim.bullet.frame_pose(sim.params.depth_camera.depth_frame)
        pts = transform_points(depth_to_points(depth, cam)[::2, ::2], rot, pos)
        occ = load_map(str(ROOT / "chefbot_navigation" / "maps" / "hotel_world_map.yaml"))
        layer = PointCloudLayer(occ.info, CloudLayerParams())
        cost = _median_ms(lambda: layer.update(pts, pos), n)
        rows.append(_row("point-cloud obstacle layer: one camera cloud (4 800 points) into the hotel map", "ms/cloud",
                         cost, "<= 50 ms (10 Hz in half a core)", cost <= 50))
        # the core with every camera output at 10 Hz
        seconds = 2.0 if quick else 10.0
        t0 = time.perf_counter()
        for _ in range(int(seconds / 0.1)):
            sim.set_cmd_vel(0.25, 0.3)
            for ev in sim.step(24):
                if ev.kind == "depth":
                    cloud_msg(depth_to_points(ev.data, cam), None, "f")
                elif ev.kind == "rgb":
                    _registered_msg(sim.last_rgb, rcam)
        rtf = seconds / (time.perf_counter() - t0)
        rows.append(_row("sim core: physics + all sensors + RGB 320x240 + both clouds at 10 Hz (no ROS)",
                         "x real time", rtf, ">= 1x", rtf >= 1.0))
    finally:
        sim.close()
    if quick:
        return rows
    for label, extra in (("real_time_factor 1", []), ("uncapped (real_time_factor 0)", ["real_time_factor:=0"])):
        out = subprocess.run([sys.executable, str(ROOT / "chefbot_sim" / "bench" / "ros_rate.py"), "--seconds", "20",
                              "--launch", "chefbot_sim", "navigation_demo.launch", *extra,
                              "--subscribe", *CAMERA_TOPICS], capture_output=True, text=True, timeout=200)
        lines = [ln for ln in out.stdout.splitlines() if ln.startswith("{")]
        if out.returncode != 0 or not lines:
            raise RuntimeError(f"ros_rate.py failed: {out.stderr[-500:]}")
        r = json.loads(lines[-1])
        got = r.get("received", {})
        clouds = got.get("camera/depth/points", 0) / max(r["wall_seconds"], 1e-9)
        rows.append(_row(f"full stack via ROS (navigation_demo), subscribers on every camera topic, {label}",
                         "x real time", r["x_real_time"], ">= 1x" if not extra else None,
                         r["x_real_time"] >= 0.97 if not extra else None))
        rows.append(_row(f"  ... camera/depth/points received per wall s, {label}", "Hz", clouds, None, None))
    return rows


if __name__ == "__main__":
    for row in run(quick="--quick" in sys.argv):
        print(f"{row['case']:<100} {row['ours']:>9.2f} {row['metric']:<12} goal {row['goal'] or '-'}")
