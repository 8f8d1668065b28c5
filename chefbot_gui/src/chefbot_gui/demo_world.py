"""Pure helpers of the GUI demo world (``nodes/gui_demo_world``): a stand-in for the
map server and move_base so the GUI can be tried, screenshotted and demonstrated
without the simulator.  No ROS, no Qt.
"""
from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import yaml

from chefbot_gui.geometry import Point, distance


@dataclass(frozen=True)
class MapFile:
    """A ``map_server`` map: cells row-major from the *bottom* row, values -1/0/100."""

    resolution: float
    origin: tuple[float, float, float]
    width: int
    height: int
    data: list[int]


def _read_pgm(path: Path) -> tuple[int, int, int, bytes]:
    raw = path.read_bytes()
    tokens: list[bytes] = []
    pos = 0
    while len(tokens) < 4:  # magic, width, height, maxval; '#' comments allowed between
        while raw[pos:pos + 1].isspace():
            pos += 1
        if raw[pos:pos + 1] == b"#":
            pos = raw.index(b"\n", pos) + 1
            continue
        end = pos
        while not raw[end:end + 1].isspace():
            end += 1
        tokens.append(raw[pos:end])
        pos = end
    if tokens[0] != b"P5":
        raise ValueError(f"{path}: only binary PGM (P5) is supported, got {tokens[0]!r}")
    w, h, maxval = (int(t) for t in tokens[1:])
    if maxval > 255:
        raise ValueError(f"{path}: 16-bit PGM not supported")
    pixels = raw[pos + 1:pos + 1 + w * h]
    if len(pixels) != w * h:
        raise ValueError(f"{path}: truncated image")
    return w, h, maxval, pixels


def load_map(yaml_path: str | Path) -> MapFile:
    """Read a map_server YAML + PGM (trinary mode) into occupancy values."""
    yaml_path = Path(yaml_path)
    meta = yaml.safe_load(yaml_path.read_text())
    w, h, maxval, pixels = _read_pgm(yaml_path.parent / meta["image"])
    occ_t, free_t = float(meta["occupied_thresh"]), float(meta["free_thresh"])
    negate = bool(meta.get("negate", 0))
    data: list[int] = []
    for row in range(h - 1, -1, -1):  # the image's top row is the grid's last row
        for p in pixels[row * w:(row + 1) * w]:
            occ = p / maxval if negate else (maxval - p) / maxval
            data.append(100 if occ > occ_t else 0 if occ < free_t else -1)
    ox, oy, oyaw = (list(meta["origin"]) + [0.0, 0.0, 0.0])[:3]
    return MapFile(float(meta["resolution"]), (float(ox), float(oy), float(oyaw)), w, h, data)


def aisle_route(start: Point, goal: Point, aisle_offset: float = 1.5) -> list[Point]:
    """A plausible route in the hotel's table grid: up/down to the aisle beside the
    goal's row, along it, then into the goal.  Good enough to draw; not a planner."""
    sign = -1.0 if goal[1] > start[1] else 1.0
    aisle_y = goal[1] + sign * aisle_offset if abs(goal[1] - start[1]) > 1e-6 else goal[1]
    pts = [start, (start[0], aisle_y), (goal[0], aisle_y), goal]
    out: list[Point] = [pts[0]]
    for p in pts[1:]:
        if distance(out[-1], p) > 1e-6:
            out.append(p)
    return out


def point_along(route: list[Point], s: float) -> tuple[float, float, float]:
    """Pose (x, y, heading) at arc length ``s`` (m) along a polyline, clamped to its ends."""
    for a, b in zip(route, route[1:], strict=False):
        seg = distance(a, b)
        heading = math.atan2(b[1] - a[1], b[0] - a[0])
        if s <= seg:
            t = s / seg if seg else 1.0
            return a[0] + t * (b[0] - a[0]), a[1] + t * (b[1] - a[1]), heading
        s -= seg
    if len(route) >= 2:
        a, b = route[-2], route[-1]
        return b[0], b[1], math.atan2(b[1] - a[1], b[0] - a[0])
    return route[0][0], route[0][1], 0.0
