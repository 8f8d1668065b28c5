"""The robot's footprint from its URDF collision geometry (pure).

The footprint is the convex hull of the floor projections of every collision body (boxes:
their 8 corners; cylinders: their two end circles, whatever their orientation; spheres: a
circle), in the base frame (``base_footprint``), grown by ``padding``.  Circles are
approximated by polygons circumscribing them, so the hull contains every body exactly.

Costmap use (as costmap_2d): the *inscribed* radius (largest circle around the origin inside
the footprint) decides "certainly in collision" (cost 253 at the robot centre), the
*circumscribed* radius (smallest circle around the origin containing it) "possibly in
collision"; in between the controller checks the polygon itself against lethal cells.
"""
from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from scipy.spatial import ConvexHull

CIRCLE_SIDES = 32


@dataclass(frozen=True)
class Footprint:
    """A convex polygon (N, 2) m, counter-clockwise, in the robot base frame."""

    polygon: np.ndarray

    @property
    def inscribed_radius(self) -> float:
        """Distance (m) from the origin to the nearest polygon edge."""
        a = self.polygon
        b = np.roll(a, -1, axis=0)
        d = b - a
        # distance from the origin to each edge line (convex polygon containing the origin)
        return float(np.min(np.abs(a[:, 0] * d[:, 1] - a[:, 1] * d[:, 0]) / np.hypot(d[:, 0], d[:, 1])))

    @property
    def circumscribed_radius(self) -> float:
        """Distance (m) from the origin to the farthest vertex."""
        return float(np.max(np.hypot(self.polygon[:, 0], self.polygon[:, 1])))

    def contains(self, pts: np.ndarray, tol: float = 1e-9) -> np.ndarray:
        """Which points (K, 2) m lie inside (or on) the polygon."""
        pts = np.asarray(pts, dtype=float).reshape(-1, 2)
        a = self.polygon
        d = np.roll(a, -1, axis=0) - a
        cross = d[None, :, 0] * (pts[:, None, 1] - a[None, :, 1]) - d[None, :, 1] * (pts[:, None, 0] - a[None, :, 0])
        return np.all(cross >= -tol, axis=1)

    def samples(self, spacing: float) -> np.ndarray:
        """Points (K, 2) m covering the polygon: its outline every ``spacing`` m and an inner grid."""
        a = self.polygon
        b = np.roll(a, -1, axis=0)
        out = []
        for p, q in zip(a, b, strict=True):
            n = max(int(math.ceil(np.hypot(*(q - p)) / spacing)), 1)
            t = np.arange(n)[:, None] / n
            out.append(p + t * (q - p))
        lo, hi = a.min(axis=0), a.max(axis=0)
        gx, gy = np.meshgrid(np.arange(lo[0], hi[0], spacing), np.arange(lo[1], hi[1], spacing))
        grid = np.column_stack((gx.ravel(), gy.ravel()))
        out.append(grid[self.contains(grid)])
        return np.concatenate(out)


def circle_footprint(radius: float) -> Footprint:
    """A round robot of ``radius`` m (polygon circumscribing the circle)."""
    if not radius > 0.0:
        raise ValueError(f"robot radius must be > 0 m, got {radius}")
    return Footprint(_circle(np.zeros(2), radius))


def polygon_footprint(points: Iterable[Iterable[float]], padding: float = 0.0) -> Footprint:
    """Footprint from polygon vertices [[x, y], ...] (m, base frame) grown by ``padding`` m."""
    pts = np.asarray([[float(v) for v in p] for p in points], dtype=float)
    if pts.ndim != 2 or pts.shape[1] != 2 or len(pts) < 3 or not np.all(np.isfinite(pts)):
        raise ValueError(f"footprint must be >= 3 finite [x, y] points, got {pts.tolist()}")
    return _hull(pts, padding)


def _circle(centre: np.ndarray, radius: float) -> np.ndarray:
    ang = np.linspace(0.0, 2.0 * math.pi, CIRCLE_SIDES, endpoint=False)
    r = radius / math.cos(math.pi / CIRCLE_SIDES)      # polygon around the circle, not inside it
    return centre[None, :] + r * np.column_stack((np.cos(ang), np.sin(ang)))


def _hull(pts: np.ndarray, padding: float) -> Footprint:
    if padding < 0.0:
        raise ValueError(f"footprint padding must be >= 0 m, got {padding}")
    if padding > 0.0:
        pts = np.concatenate([_circle(p, padding) for p in pts])
    try:
        hull = ConvexHull(pts)
    except Exception as exc:   # noqa: BLE001 -- scipy's QhullError: degenerate input
        raise ValueError(f"footprint points span no area: {exc}") from None
    poly = pts[hull.vertices]           # counter-clockwise for 2-D hulls
    fp = Footprint(poly)
    if not fp.contains(np.zeros((1, 2)))[0]:
        raise ValueError("footprint does not contain the robot origin (base frame): "
                         f"{np.round(poly, 3).tolist()}")
    return fp


def body_outline(kind: str, size: tuple[float, ...], pose: np.ndarray) -> np.ndarray:
    """Floor projection (K, 2) m of one collision primitive whose pose in the base frame is ``pose`` (4x4).

    Box: 8 corners; cylinder: both end circles; sphere: a circle.  Meshes raise ValueError.
    """
    rot, centre = pose[:3, :3], pose[:3, 3]
    if kind == "box":
        hx, hy, hz = (0.5 * s for s in size)
        corners = np.array([[sx * hx, sy * hy, sz * hz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        pts = corners @ rot.T + centre
    elif kind == "cylinder":
        radius, length = size
        ang = np.linspace(0.0, 2.0 * math.pi, CIRCLE_SIDES, endpoint=False)
        r = radius / math.cos(math.pi / CIRCLE_SIDES)
        ring = np.column_stack((r * np.cos(ang), r * np.sin(ang), np.zeros_like(ang)))
        ends = np.concatenate([ring + [0.0, 0.0, -0.5 * length], ring + [0.0, 0.0, 0.5 * length]])
        pts = ends @ rot.T + centre
    elif kind == "sphere":
        return _circle(centre[:2], size[0])
    else:
        raise ValueError(f"cannot project a <{kind}> collision body (use boxes, cylinders, spheres)")
    return pts[:, :2]


def collision_outlines(model, base: str = "base_footprint") -> list[tuple[str, np.ndarray]]:
    """(link name, floor projection) of every collision body of a parsed URDF
    (:class:`chefbot_description.model.RobotModel`), in frame ``base`` with all joints at zero."""
    from chefbot_description.model import frame_transform, pose_matrix

    out = []
    for name, link in model.links.items():
        if not link.collisions:
            continue
        link_pose = frame_transform(model, name, base)
        for geom in link.collisions:
            out.append((name, body_outline(geom.kind, geom.size, link_pose @ pose_matrix(geom.xyz, geom.rpy))))
    return out


def footprint_from_urdf(urdf_xml: str, base: str = "base_footprint", padding: float = 0.0) -> Footprint:
    """Convex hull of every collision body's floor projection, grown by ``padding`` m.

    ValueError when the URDF cannot be parsed, has no collision geometry or ``base`` is not an
    ancestor of the links.
    """
    from chefbot_description.model import parse_urdf

    outlines = collision_outlines(parse_urdf(urdf_xml), base)
    if not outlines:
        raise ValueError("the URDF has no <collision> geometry to make a footprint from")
    return _hull(np.concatenate([o for _, o in outlines]), padding)


def resolve_footprint(spec: str, padding: float, robot_radius: float,
                      urdf_xml: str | None, base: str = "base_footprint") -> tuple[Footprint, str]:
    """The footprint a ``costmap/footprint`` param asks for, and a line saying where it came from.

    ``urdf``: from ``urdf_xml`` (the ``robot_description`` param) in its frame ``base`` (the
    robot_base_frame, e.g. ``chefbot1/base_footprint`` with a frame prefix); without one, the round
    ``robot_radius`` with a note.  ``radius``: round.  ``[[x, y], ...]``: that polygon.
    ValueError names the problem.
    """
    spec = spec.strip()
    if spec == "radius":
        return circle_footprint(robot_radius), f"round, robot_radius {robot_radius:g} m"
    if spec == "urdf":
        if not urdf_xml:
            return (circle_footprint(robot_radius),
                    f"round, robot_radius {robot_radius:g} m (no robot_description to read the URDF from)")
        fp = footprint_from_urdf(urdf_xml, base, padding=padding)
        return fp, f"URDF collision bodies + {padding:g} m padding"
    if spec.startswith("["):
        import yaml

        try:
            pts = yaml.safe_load(spec)
        except yaml.YAMLError as exc:
            raise ValueError(f"costmap/footprint is not a list of [x, y] points: {exc}") from None
        return polygon_footprint(pts, padding), f"polygon param + {padding:g} m padding"
    raise ValueError(f"costmap/footprint must be urdf, radius or [[x, y], ...], got {spec!r}")
