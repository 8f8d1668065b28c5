"""Single-lane zones of a site map: the aisles two robots cannot pass each other in (pure numpy/scipy).

An aisle's width at a point of its centre line is twice the distance from there to the nearest
obstacle.  The centre lines are the free space's medial axis (scikit-image); the distance is
scipy's Euclidean distance transform.  A centre-line cell is *single-lane* where a robot fits
(width >= its diameter) but two do not (width < ``two_lane_width``).  Each connected run of
single-lane centre-line cells is one zone.  The zone's *area* is where two robots cannot be side by
side: the free cells a robot's body can reach (covered by a free disc of the robot's radius) but no
free disc ``two_lane_width`` across covers (a morphological opening of the free space by each disc,
from distance transforms), in the connected pieces its centre line runs through.  So the area is
the aisle up to its walls and the narrow part of its mouth, and no further: a robot driving along a
wider aisle past the mouth does not touch it.  Where a zone's centre line
meets a wider one is a *mouth*; the zone's *holding point* for that mouth lies on the wide centre
line, far enough out that a robot waiting there keeps its whole body outside the zone.

Zones closer to each other than :attr:`ZoneConfig.merge_distance` are merged into one: a robot
that stops to wait for the next zone, ``hold_distance`` (plus a braking margin) from it, must by then
be clear of the zone it has just left (the reservation rule's "no hold and wait",
:mod:`chefbot_fleet.reservations`).

Units: metres; cells are (row, col) of the map (row 0 at the origin's y, as map_server's data).
Unknown cells count as obstacles.
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy import ndimage
from skimage.morphology import medial_axis

from chefbot_common.grid import OccupancyMap

FREE_MAX = 25          # occupancy values up to this are free space (map_server's free_thresh 0.196 -> 19.6 %)
EIGHT = np.ones((3, 3), bool)


@dataclass(frozen=True)
class ZoneConfig:
    """What makes an aisle single-lane, and where robots wait outside one."""

    robot_radius: float = 0.178        # [m] the robot's half-width (ChefBot's round base: 0.178 m; the 0.279 m
                                       # camera bar across its front stays within that sideways)
    passing_margin: float = 0.15       # [m] free width two robots need besides their two bodies to pass
    hold_clearance: float = 0.10       # [m] gap between a waiting robot's body and a robot that has just
                                       # left the zone (its body 2 radii out of the zone's area)
    hold_margin: float = 0.10          # [m] a waiting robot stops up to this much before hold_distance (braking)
    min_length: float = 0.5            # [m] shorter single-lane runs are ignored: the tip of the centre line
                                       # running into a room corner narrows through the band over ~0.36 m

    def __post_init__(self) -> None:
        if not self.robot_radius > 0:
            raise ValueError(f"robot_radius must be > 0 m, got {self.robot_radius}")
        if self.passing_margin < 0 or self.hold_clearance < 0 or self.min_length < 0:
            raise ValueError("passing_margin, hold_clearance and min_length must be >= 0 m")

    @property
    def hold_distance(self) -> float:
        """[m] from the zone's area to a waiting robot's centre: a robot coming out of the zone gets its
        whole body out (two radii) before it must pass the waiting one, plus the clearance."""
        return 3.0 * self.robot_radius + self.hold_clearance

    @property
    def merge_distance(self) -> float:
        """[m] zones closer than this are one zone: a robot waiting hold_distance + hold_margin from one
        is then always at least a robot radius clear of the other."""
        return self.hold_distance + self.hold_margin + self.robot_radius

    @property
    def two_lane_width(self) -> float:
        """[m] the narrowest aisle two robots pass each other in: two diameters and the margin."""
        return 4.0 * self.robot_radius + self.passing_margin


@dataclass
class Zone:
    """One single-lane zone: its cells, narrowest and widest width (m), length along its centre lines (m)
    and holding points (world x, y; one per wider centre line it opens onto, none for a zone that is a
    whole closed room).  A zone may be several aisles closer to each other than ``merge_distance``."""

    id: int
    cells: np.ndarray = field(repr=False)          # (N, 2) int (row, col) of the zone's area
    min_width: float
    max_width: float
    length: float
    holding_points: list[tuple[float, float]]


@dataclass
class ZoneMap:
    """Every zone of a map and the label image (0 = no zone, k = zone k) to look points up in."""

    info: object                                   # chefbot_common.grid.GridInfo of the map
    labels: np.ndarray = field(repr=False)         # (H, W) int32
    zones: list[Zone]
    distance: dict[int, np.ndarray] = field(default_factory=dict, repr=False)   # zone id -> (H, W) m to its area
    clearance: np.ndarray | None = field(default=None, repr=False)   # (H, W) m from each cell to the nearest obstacle

    def zone_at(self, x: float, y: float) -> int:
        """The zone id at world (x, y); 0 outside every zone (and outside the map)."""
        row, col = self.info.world_to_cell(x, y)
        if not (0 <= row < self.labels.shape[0] and 0 <= col < self.labels.shape[1]):
            return 0
        return int(self.labels[row, col])

    def keep_out(self, radius: float) -> np.ndarray:
        """(H, W) bool: where a robot of ``radius`` m centred there would touch a zone."""
        out = np.zeros(self.labels.shape, bool)
        for d in self.distance.values():
            out |= d <= radius
        return out

    def zones_along(self, xy: np.ndarray) -> list[int]:
        """The zones a path (N, 2 world points) enters, in order, each once per entry."""
        out: list[int] = []
        prev = 0
        for x, y in np.asarray(xy, float).reshape(-1, 2):
            z = self.zone_at(float(x), float(y))
            if z and z != prev:
                out.append(z)
            prev = z
        return out


def extract_zones(grid: OccupancyMap, cfg: ZoneConfig | None = None) -> ZoneMap:
    """The single-lane zones of ``grid`` (see the module docstring)."""
    cfg = cfg or ZoneConfig()
    info = grid.info
    res = info.resolution
    free = (grid.data >= 0) & (grid.data <= FREE_MAX)
    # a fixed seed for medial_axis's random tie-breaking: the same map always gives the same zones
    skel, dist = medial_axis(free, return_distance=True, rng=0)
    # the width at a centre-line cell: twice the distance from its centre to the nearest obstacle cell's
    # edge (the transform measures to that cell's centre: half a cell more)
    width = 2.0 * np.maximum(dist - 0.5, 0.0) * res
    fits = width >= 2.0 * cfg.robot_radius
    narrow = skel & fits & (width < cfg.two_lane_width)
    runs, n = ndimage.label(narrow, structure=EIGHT)
    # the pieces of single-lane area, each run's pieces, and runs sharing a piece joined
    pieces, _ = ndimage.label(_single_lane_area(free, dist, res, cfg), structure=EIGHT)
    piece_runs: dict[int, list[int]] = {}
    for k in range(1, n + 1):
        if _line_length(runs == k, res) < cfg.min_length:
            continue
        for piece in np.unique(pieces[runs == k]):
            if piece:
                piece_runs.setdefault(int(piece), []).append(k)
    owner = np.where(np.isin(pieces, list(piece_runs)), pieces, 0)
    labels = np.zeros(grid.data.shape, np.int32)
    zones: list[Zone] = []
    wide = skel & fits & ~narrow
    wide_runs, _ = ndimage.label(wide, structure=EIGHT)
    distance: dict[int, np.ndarray] = {}
    for group in _merge_close(sorted(piece_runs), owner, res, cfg.merge_distance):
        line = np.isin(runs, [k for piece in group for k in piece_runs[piece]])
        area = np.isin(owner, group)
        zid = len(zones) + 1
        labels[area] = zid
        distance[zid] = ndimage.distance_transform_edt(~area) * res
        w = width[line]
        zones.append(Zone(zid, np.argwhere(area), float(w.min()), float(w.max()), _line_length(line, res),
                          _holding_points(line, wide_runs, distance[zid], info, cfg)))
    return ZoneMap(info, labels, zones, distance, np.maximum(dist - 0.5, 0.0) * res)


def _single_lane_area(free: np.ndarray, dist: np.ndarray, res: float, cfg: ZoneConfig) -> np.ndarray:
    """Free cells within reach of a robot's body but of no free disc ``two_lane_width`` across.
    ``dist``: cells from each cell to the nearest obstacle cell; a disc of radius R (m) centred on a
    cell is free when (dist - 0.5) * res >= R (as the widths are measured)."""

    def covered(radius: float) -> np.ndarray:
        centres = (dist - 0.5) * res >= radius
        if not centres.any():
            return np.zeros_like(free)
        return ndimage.distance_transform_edt(~centres) * res <= radius

    return free & covered(cfg.robot_radius) & ~covered(cfg.two_lane_width / 2.0)


def _merge_close(runs: list[int], owner: np.ndarray, res: float, within: float) -> list[list[int]]:
    """Groups of area labels (``owner``) closer than ``within`` m to each other (transitively), in label
    order."""
    parent = {k: k for k in runs}

    def find(k: int) -> int:
        while parent[k] != k:
            parent[k] = parent[parent[k]]
            k = parent[k]
        return k

    for i, a in enumerate(runs):
        d = ndimage.distance_transform_edt(owner != a) * res
        for b in runs[i + 1:]:
            if find(a) != find(b) and float(d[owner == b].min()) < within:
                parent[find(b)] = find(a)
    groups: dict[int, list[int]] = {}
    for k in runs:
        groups.setdefault(find(k), []).append(k)
    return sorted(groups.values())


def _line_length(line: np.ndarray, res: float) -> float:
    """Length (m) of an 8-connected centre line: straight steps 1 cell, diagonal ones sqrt(2) (each
    neighbouring pair once)."""
    a = line.astype(np.int32)
    straight = np.count_nonzero(a[1:, :] & a[:-1, :]) + np.count_nonzero(a[:, 1:] & a[:, :-1])
    diagonal = np.count_nonzero(a[1:, 1:] & a[:-1, :-1]) + np.count_nonzero(a[1:, :-1] & a[:-1, 1:])
    return float((straight + diagonal * np.sqrt(2.0)) * res) if a.sum() > 1 else float(res)


def _holding_points(line: np.ndarray, wide_runs: np.ndarray, to_area: np.ndarray, info,
                    cfg: ZoneConfig) -> list[tuple[float, float]]:
    """Per mouth (a run of wide centre line, labelled in ``wide_runs``, touching the zone's line), the
    wide centre-line cell nearest the mouth at least ``cfg.hold_distance`` from the zone's area
    (``to_area``: m from every cell): there the line is wide enough for two robots, so the one
    leaving the zone passes the waiting one."""
    touching = ndimage.binary_dilation(line, structure=EIGHT) & (wide_runs > 0)
    if not touching.any():
        return []
    need = cfg.hold_distance
    points = []
    for run in np.unique(wide_runs[touching]):
        cand = (wide_runs == run) & (to_area >= need)
        if not cand.any():
            continue
        # nearest such cell to the mouth, by geodesic distance along the wide line: approximated by the
        # straight distance to the mouth cells (the line leaves the mouth without turning back)
        mouth = np.argwhere(touching & (wide_runs == run))
        rc = np.argwhere(cand)
        d = np.min(np.hypot(rc[:, None, 0] - mouth[None, :, 0], rc[:, None, 1] - mouth[None, :, 1]), axis=1)
        r, c = rc[int(np.argmin(d))]
        x, y = info.cell_to_world(r, c)
        points.append((float(x), float(y)))
    return points
