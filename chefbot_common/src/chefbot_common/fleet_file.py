"""The robots of a site, read from a fleet YAML (pure).

One file per site, beside its map and tables file in ``chefbot_navigation/maps/``
(``hotel_fleet.yaml``, ``cafe_fleet.yaml``).  Format::

    frame: map
    site: hotel
    kitchen: {x: -1.6, y: -3.5, yaw: 3.1416}   # optional: where the dispatcher's robots load plates
    robots:
      - name: chefbot1
        parking: {x: 0.0, y: 0.0, yaw: 0.0}   # where it waits when it has nothing to do
        start: {x: 0.0, y: 0.0, yaw: 0.0}     # where it is switched on (default: its parking pose)
        charger: {x: -2.6, y: 1.0, yaw: 3.1416}   # optional: its charging pose

Poses are in the site map's frame (m, rad; ``yaw`` defaults to 0).  The kitchen pose (read by
:func:`load_kitchen`) is one robot's at a time, so it must be clear of every robot's poses.  Names are the robots'
ROS namespaces, so they must be ROS graph names without a slash (``chefbot1``, ``tray_bot``).
The simulator starts robot *i* of ``robots:=N`` at the *i*-th entry's start pose; the fleet
nodes read the rest.  :class:`FleetFileError` names the file and the entry of anything wrong,
including two robots whose start, parking or charger poses would put their bodies into each
other.
"""
from __future__ import annotations

import re
from dataclasses import dataclass
from pathlib import Path

from chefbot_common.geometry import Pose2D
from chefbot_common.tables import TablesError, parse_pose, read_yaml_file

#: Closest two robots' reference poses may be (m): ChefBot's 0.356 m base diameter and a margin.
MIN_APART = 0.45
_NAME = re.compile(r"^[A-Za-z][A-Za-z0-9_]*$")


class FleetFileError(ValueError):
    """A fleet file is invalid; the message names the file and the entry."""


@dataclass(frozen=True)
class FleetRobot:
    """One robot of a site: its name (ROS namespace) and poses in the map frame."""

    name: str
    parking: Pose2D
    start: Pose2D
    charger: Pose2D | None = None


def load_fleet(path: str | Path, min_apart: float = MIN_APART) -> list[FleetRobot]:
    """The robots of a fleet file, in file order (see the module docstring for the format).
    ``min_apart`` (m) is the least distance between two robots' start, parking and charger poses."""
    path = Path(path)
    data = read_yaml_file(path, "fleet file", FleetFileError)
    if not isinstance(data, dict) or not isinstance(data.get("robots"), list):
        raise FleetFileError(f"{path}: expected a mapping with a 'robots' list")
    unknown = set(data) - {"frame", "site", "robots", "kitchen"}
    if unknown:
        raise FleetFileError(f"{path}: unknown top-level key(s) {sorted(unknown)}")
    if data.get("frame", "map") != "map":
        raise FleetFileError(f"{path}: frame must be 'map', got {data.get('frame')!r}")
    if not data["robots"]:
        raise FleetFileError(f"{path}: 'robots' lists no robot")
    robots = [_robot(entry, f"{path}: robots[{i}]") for i, entry in enumerate(data["robots"])]
    names = [r.name for r in robots]
    twice = sorted({n for n in names if names.count(n) > 1})
    if twice:
        raise FleetFileError(f"{path}: robot name(s) {twice} listed twice")
    for kind in ("parking", "start", "charger"):
        _check_apart(robots, kind, min_apart, path)
    kitchen = _kitchen(data, path)
    if kitchen is not None:
        for r in robots:
            for kind in ("parking", "start", "charger"):
                pose = getattr(r, kind)
                if pose is not None and pose.distance(kitchen) < min_apart:
                    raise FleetFileError(f"{path}: the kitchen is {pose.distance(kitchen):.2f} m from {r.name}'s "
                                         f"{kind} pose, closer than {min_apart:g} m: a robot standing there would "
                                         "block it")
    return robots


def load_kitchen(path: str | Path) -> Pose2D | None:
    """The fleet file's kitchen pose (None when it has none); the file is checked as :func:`load_fleet`."""
    load_fleet(path)
    return _kitchen(read_yaml_file(Path(path), "fleet file", FleetFileError), Path(path))


def _kitchen(data: dict, path: Path) -> Pose2D | None:
    if data.get("kitchen") is None:
        return None
    try:
        return parse_pose(data["kitchen"], f"{path}: kitchen")
    except TablesError as e:
        raise FleetFileError(str(e)) from None


def _robot(entry: object, where: str) -> FleetRobot:
    if not isinstance(entry, dict):
        raise FleetFileError(f"{where}: expected a mapping with name, parking (start, charger), got {entry!r}")
    unknown = set(entry) - {"name", "parking", "start", "charger"}
    if unknown:
        raise FleetFileError(f"{where}: unknown key(s) {sorted(unknown)}")
    name = entry.get("name")
    if not isinstance(name, str) or not _NAME.match(name):
        raise FleetFileError(f"{where}: name must be a ROS name without slashes (letter, then letters, digits, "
                             f"'_'), got {name!r}")
    where = f"{where} ({name})"
    if "parking" not in entry:
        raise FleetFileError(f"{where}: missing the 'parking' pose")
    try:
        parking = parse_pose(entry["parking"], f"{where}.parking")
        start = parse_pose(entry["start"], f"{where}.start") if "start" in entry else parking
        charger = parse_pose(entry["charger"], f"{where}.charger") if entry.get("charger") is not None else None
    except TablesError as e:
        raise FleetFileError(str(e)) from None
    return FleetRobot(name, parking, start, charger)


def _check_apart(robots: list[FleetRobot], kind: str, min_apart: float, path: Path) -> None:
    poses = [(r.name, getattr(r, kind)) for r in robots if getattr(r, kind) is not None]
    for i, (na, pa) in enumerate(poses):
        for nb, pb in poses[i + 1:]:
            d = pa.distance(pb)
            if d < min_apart:
                raise FleetFileError(f"{path}: the {kind} poses of {na} and {nb} are {d:.2f} m apart, closer than "
                                     f"{min_apart:g} m: the robots would stand in each other")


def select(robots: list[FleetRobot], count: int, path: str | Path = "fleet file") -> list[FleetRobot]:
    """The first ``count`` robots (``robots:=N``); FleetFileError when the file has fewer."""
    if count < 1:
        raise FleetFileError(f"robots must be >= 1, got {count}")
    if count > len(robots):
        raise FleetFileError(f"{path}: robots:={count} asked, but the file lists {len(robots)} "
                             f"({', '.join(r.name for r in robots)}); add entries for more")
    return robots[:count]
