"""Named delivery poses of a restaurant (``home``, ``table_1``, ``bar`` ...) read from a tables YAML (pure).

Every pose but ``home`` is a destination, whatever its name, unless the file lists its
destinations (``destinations: [...]``); :func:`load_destinations` gives them.

The site's tables file lives beside its map in ``chefbot_navigation/maps/``;
the GUI, the demo and the scenario tests read it through :func:`load_tables`.
"""
from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import yaml

from chefbot_common.geometry import Pose2D


class TablesError(ValueError):
    """A tables file is invalid; the message names the file and the entry."""


#: Poses that are never destinations: the robot's start and rest pose.
NOT_DESTINATIONS = frozenset({"home"})


def _number(v: Any, where: str) -> float:
    """``v`` as a finite float, or :class:`TablesError` naming ``where``."""
    if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(float(v)):
        raise TablesError(f"{where}: expected a finite number, got {v!r}")
    return float(v)


def parse_pose(p: Any, where: str) -> Pose2D:
    """A ``{x, y, yaw}`` mapping as a Pose2D (yaw default 0), or :class:`TablesError` naming ``where``."""
    if not isinstance(p, dict):
        raise TablesError(f"{where}: expected a mapping {{x, y, yaw}}, got {p!r}")
    unknown = set(p) - {"x", "y", "yaw"}
    if unknown:
        raise TablesError(f"{where}: unknown key(s) {sorted(unknown)}")
    for key in ("x", "y"):
        if key not in p:
            raise TablesError(f"{where}: missing field '{key}'")
    return Pose2D(_number(p["x"], f"{where}.x"), _number(p["y"], f"{where}.y"),
                  _number(p.get("yaw", 0.0), f"{where}.yaw"))


def load_map_in_world(path: str | Path) -> Pose2D:
    """The pose (m, rad) of the tables file's map frame in the simulated world's frame.

    Test-oracle data for a map that is not the world raster (a SLAM map: its frame
    is the robot's odometry frame at the first scan): the demo spawns the robot and
    compares ground truth through it.  Written by ``align_tables``; identity when
    absent.  Product nodes do not read it.  Raises :class:`TablesError`.
    """
    data, _ = _read(Path(path))   # validates the whole file
    return parse_pose(data["map_in_world"], f"{path}: map_in_world") if "map_in_world" in data else Pose2D()


def format_tables(poses: dict[str, Pose2D], header: str, world: str | None = None,
                  map_in_world: Pose2D | None = None) -> str:
    """A tables YAML (the format of :func:`load_tables`): ``header`` as ``#`` comment lines, then the poses."""
    lines = [f"# {line}".rstrip() for line in header.splitlines()]
    lines.append("frame: map")
    if world:
        lines.append(f"world: {world}")
    if map_in_world is not None:
        m = map_in_world
        lines.append(f"map_in_world: {{x: {m.x:.4f}, y: {m.y:.4f}, yaw: {m.yaw:.5f}}}")
    lines.append("poses:")
    lines += [f"  {name}: {{x: {p.x:.4f}, y: {p.y:.4f}, yaw: {p.yaw:.5f}}}" for name, p in poses.items()]
    return "\n".join(lines) + "\n"


def load_tables(path: str | Path) -> dict[str, Pose2D]:
    """Load the named delivery poses (``home``, ``table_1`` ...) of a tables YAML.

    Format::

        frame: map
        poses:
          home:    {x: 0.0, y: 0.0, yaw: 0.0}
          table_1: {x: 2.05, y: -3.0, yaw: 0.0}

    ``yaw`` in rad (default 0).  ``home`` is required; names are unique by YAML
    construction and may be anything (``table_1``, ``round_1``, ``bar``).  An optional
    ``destinations: [name, ...]`` says which poses are destinations (default: every
    pose but ``home``; see :func:`load_destinations`).  An optional
    ``map_in_world: {x, y, yaw}`` is test-oracle data (see :func:`load_map_in_world`).
    Raises :class:`TablesError` naming the file and the entry.
    """
    return _read(Path(path))[1]


def read_yaml_file(path: Path, what: str, error: type[ValueError]) -> Any:
    """The parsed YAML of ``path`` (a site file: ``what`` names its kind in messages), or ``error``
    naming the file: unreadable, not UTF-8, or invalid YAML."""
    try:
        return yaml.safe_load(path.read_text(encoding="utf-8"))
    except OSError as e:
        raise error(f"{path}: cannot read {what}: {e.strerror}") from e
    except UnicodeDecodeError as e:
        raise error(f"{path}: not UTF-8 text (byte {e.start}: {e.reason})") from e
    except yaml.YAMLError as e:
        raise error(f"{path}: invalid YAML: {e}") from e


def _read(path: Path) -> tuple[dict, dict[str, Pose2D]]:
    """The parsed YAML of a tables file and its poses, the whole file validated (:func:`load_tables`)."""
    data = read_yaml_file(path, "tables file", TablesError)
    if not isinstance(data, dict) or not isinstance(data.get("poses"), dict):
        raise TablesError(f"{path}: expected a mapping with a 'poses' mapping")
    unknown = set(data) - {"frame", "world", "poses", "map_in_world", "destinations"}
    if unknown:
        raise TablesError(f"{path}: unknown top-level key(s) {sorted(unknown)}")
    frame = data.get("frame", "map")
    if frame != "map":
        raise TablesError(f"{path}: frame must be 'map', got {frame!r}")
    if "map_in_world" in data:
        parse_pose(data["map_in_world"], f"{path}: map_in_world")
    out = {str(name): parse_pose(p, f"{path}: poses.{name}") for name, p in data["poses"].items()}
    if "home" not in out:
        raise TablesError(f"{path}: missing the 'home' pose")
    if "destinations" in data:
        _destinations(data, out, path)   # a file with only 'home' is fine here, not to deliver to
    return data, out


def _destinations(data: dict, poses: dict[str, Pose2D], path: Path) -> list[str]:
    """The destination names of a parsed tables file (file order), or :class:`TablesError`."""
    if "destinations" in data:
        listed = data["destinations"]
        if not isinstance(listed, list) or not all(isinstance(n, str) for n in listed):
            raise TablesError(f"{path}: destinations must be a list of pose names, got {listed!r}")
        unknown = [n for n in listed if n not in poses]
        if unknown:
            raise TablesError(f"{path}: destinations names unknown pose(s) {unknown}; poses: {sorted(poses)}")
        reserved = [n for n in listed if n in NOT_DESTINATIONS]
        if reserved:
            raise TablesError(f"{path}: {reserved} cannot be a destination (the robot's start and rest pose)")
        if len(set(listed)) != len(listed):
            raise TablesError(f"{path}: destinations lists a pose twice: {listed}")
        names = list(listed)
    else:
        names = [n for n in poses if n not in NOT_DESTINATIONS]
    if not names:
        raise TablesError(f"{path}: no destinations: add a pose besides 'home' (any name: table_1, bar, ...)")
    return names


def load_destinations(path: str | Path) -> list[str]:
    """The destinations of a tables file in file order: its ``destinations`` list, else every pose
    but ``home``.  Raises :class:`TablesError` naming the file (zero destinations is an error)."""
    data, poses = _read(Path(path))
    return _destinations(data, poses, Path(path))
