"""Frontier exploration (pure): where to drive next on a growing occupancy map.

A frontier cell is a free cell with an unknown 4-neighbour; frontier cells are
grouped 8-connected (``scipy.ndimage.label``).  For every group big enough, the
goal is the reachable free cell closest to the group's centroid that keeps
``clearance`` m from obstacles and lies within ``approach`` m of the group.
Reachability and the travel cost come from one geodesic distance transform
from the robot over the safe free cells (scikit-image's ``MCP_Geometric``).
The next goal minimises travel - ``gain_weight`` * frontier length; the goal
heading faces the frontier, so a narrow depth camera looks into the unknown.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import ndimage
from skimage.graph import MCP_Geometric

from chefbot_common.geometry import Pose2D
from chefbot_common.grid import FREE, UNKNOWN, OccupancyMap


@dataclass
class ExploreConfig:
    """Goal selection parameters (m unless stated)."""

    clearance: float = 0.5           # goal distance from any occupied cell
    robot_radius: float = 0.2        # travel corridor distance from occupied cells
    approach: float = 1.0            # goal at most this far from its frontier
    min_frontier: float = 0.3        # frontier length (m, cells * resolution) worth a visit
    gain_weight: float = 1.0         # m of travel a metre of frontier is worth
    blacklist_radius: float = 0.5    # failed goals block candidates this close

    def __post_init__(self) -> None:
        for name in ("clearance", "robot_radius", "approach", "min_frontier", "blacklist_radius"):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name} must be > 0 m, got {getattr(self, name)}")
        if self.gain_weight < 0:
            raise ValueError(f"gain_weight must be >= 0, got {self.gain_weight}")


@dataclass(frozen=True)
class ExploreNodeParams:
    """The explore node's own parameters (s, rad/s)."""

    mode: str = "frontier"              # frontier | waypoints
    map_frame: str = "map"
    base_frame: str = "base_footprint"
    goal_timeout: float = 60.0          # s (sim) per goal
    max_duration: float = 900.0         # s (sim) for the whole run
    spin_speed: float = 0.8             # rad/s of the look-around spins (0: none)
    recheck_period: float = 2.0         # s, is the current goal's frontier still open?

    def __post_init__(self) -> None:
        if self.mode not in ("frontier", "waypoints"):
            raise ValueError(f"mode must be 'frontier' or 'waypoints', got {self.mode!r}")
        if not (self.goal_timeout > 0 and self.max_duration > 0 and self.recheck_period > 0 <= self.spin_speed):
            raise ValueError("goal_timeout, max_duration, recheck_period must be > 0 s and spin_speed >= 0")


@dataclass
class Frontier:
    """A frontier group: centroid (m), length (m), goal pose, travel cost (m)."""

    centroid: tuple[float, float]
    length: float
    goal: Pose2D
    travel: float


def frontier_mask(occ: OccupancyMap) -> np.ndarray:
    """Boolean mask of free cells with an unknown 4-neighbour."""
    free = occ.data == FREE
    unk = occ.data == UNKNOWN
    near = np.zeros_like(unk)
    near[1:, :] |= unk[:-1, :]
    near[:-1, :] |= unk[1:, :]
    near[:, 1:] |= unk[:, :-1]
    near[:, :-1] |= unk[:, 1:]
    return free & near


def find_frontiers(occ: OccupancyMap, robot: Pose2D, cfg: ExploreConfig,
                   blacklist: list[tuple[float, float]] | None = None) -> list[Frontier]:
    """Reachable frontier groups with their goals, best first (see the module docstring)."""
    info, res = occ.info, occ.info.resolution
    occupied = occ.data > 50
    dist = ndimage.distance_transform_edt(~occupied) * res if occupied.any() else np.full(occ.data.shape, 1e9)
    free = occ.data == FREE
    passable = free & (dist >= cfg.robot_radius)
    r0, c0 = info.world_to_cell(robot.x, robot.y)
    if not info.inside(r0, c0):
        return []
    # the robot's own cell may be unknown or close to a wall: let it start from there
    passable[max(r0 - 2, 0):r0 + 3, max(c0 - 2, 0):c0 + 3] |= occ.data[max(r0 - 2, 0):r0 + 3,
                                                                        max(c0 - 2, 0):c0 + 3] != 100
    cost = np.where(passable, 1.0, np.inf)
    travel, _ = MCP_Geometric(cost).find_costs([(int(r0), int(c0))])
    travel = travel * res
    labels, n = ndimage.label(frontier_mask(occ), structure=np.ones((3, 3)))
    if n == 0:
        return []
    goal_ok = passable & (dist >= cfg.clearance) & np.isfinite(travel)
    gr, gc = np.nonzero(goal_ok)
    gx, gy = info.cell_to_world(gr, gc)
    out: list[Frontier] = []
    for lab, sl in enumerate(ndimage.find_objects(labels), start=1):
        rr, cc = np.nonzero(labels[sl] == lab)
        length = len(rr) * res
        if length < cfg.min_frontier:
            continue
        fx, fy = info.cell_to_world(rr + sl[0].start, cc + sl[1].start)
        cx, cy = float(fx.mean()), float(fy.mean())
        # candidate goals near this frontier: within `approach` of its nearest frontier cell
        d_front = np.full(len(gx), np.inf)
        near = (np.abs(gx - cx) < cfg.approach + length) & (np.abs(gy - cy) < cfg.approach + length)
        if not near.any():
            continue
        idx = np.nonzero(near)[0]
        step = max(1, len(fx) // 50)
        d = np.hypot(gx[idx, None] - fx[None, ::step], gy[idx, None] - fy[None, ::step]).min(axis=1)
        d_front[idx] = d
        cand = d_front <= cfg.approach
        for bx, by in blacklist or []:
            cand &= np.hypot(gx - bx, gy - by) > cfg.blacklist_radius
        if not cand.any():
            continue
        k = np.nonzero(cand)[0][np.argmin(np.hypot(gx[cand] - cx, gy[cand] - cy))]
        x, y = float(gx[k]), float(gy[k])
        # face the frontier; a goal on the frontier itself faces on along the way it was reached
        # (from the known side into the unknown)
        if math.hypot(cy - y, cx - x) > 0.3:
            yaw = math.atan2(cy - y, cx - x)
        else:
            yaw = math.atan2(y - robot.y, x - robot.x) if math.hypot(y - robot.y, x - robot.x) > 1e-6 else robot.yaw
        out.append(Frontier((cx, cy), length, Pose2D(x, y, yaw), float(travel[gr[k], gc[k]])))
    out.sort(key=lambda f: f.travel - cfg.gain_weight * f.length)
    return out


def known_area(occ: OccupancyMap) -> tuple[float, float]:
    """(known m^2, free m^2) of the map."""
    a = occ.info.resolution ** 2
    return float((occ.data != UNKNOWN).sum() * a), float((occ.data == FREE).sum() * a)


def progress(occ: OccupancyMap, n_frontiers: int, elapsed: float) -> str:
    """One progress line: known and free area (m^2), frontiers left, elapsed time (s)."""
    known, free = known_area(occ)
    extent = occ.info.width * occ.info.height * occ.info.resolution ** 2
    return (f"explore: known {known:.1f} m^2 ({100 * known / max(extent, 1e-9):.0f} % of the map's extent), "
            f"free {free:.1f} m^2, {n_frontiers} frontiers left, elapsed {elapsed:.0f} s")
