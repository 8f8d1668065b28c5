"""What one robot of a fleet knows about itself (pure, no rospy): its entry of the site's fleet file,
the part of its plan still ahead, what it is doing."""
from __future__ import annotations

import numpy as np

from chefbot_common.fleet_file import FleetFileError, FleetRobot, load_fleet
from chefbot_common.geometry import Pose2D
from chefbot_navigation.robots_layer import from_nearest

#: amcl's pose covariance is a row-major 6 x 6 (x, y, z, roll, pitch, yaw) matrix.
COV_X, COV_Y, COV_YAW = 0, 7, 35


def robot_name(param: str, namespace: str) -> str:
    """The robot's name: ``param`` when given, else the node's namespace (``/chefbot2/`` → ``chefbot2``).
    FleetFileError when neither names one robot (a node outside a robot's namespace)."""
    name = param or namespace.strip("/")
    if not name or "/" in name:
        raise FleetFileError(f"cannot tell which robot this is: set ~robot, or run the node in the robot's "
                             f"namespace (it runs in {namespace!r})")
    return name


def find_robot(path: str, name: str) -> FleetRobot:
    """The entry ``name`` of the fleet file ``path`` (FleetFileError names the robots it lists)."""
    robots = load_fleet(path)
    for r in robots:
        if r.name == name:
            return r
    raise FleetFileError(f"{path}: no robot '{name}' (robots: {', '.join(r.name for r in robots)})")


def initial_covariance(var_xy: float, var_yaw: float) -> list[float]:
    """The 36 covariance entries of an initial pose with variance ``var_xy`` (m²) in x and y and
    ``var_yaw`` (rad²) in heading."""
    if not (var_xy > 0 and var_yaw > 0):
        raise ValueError(f"initial variances must be > 0, got {var_xy}, {var_yaw}")
    cov = [0.0] * 36
    cov[COV_X], cov[COV_Y], cov[COV_YAW] = float(var_xy), float(var_xy), float(var_yaw)
    return cov


def saved_pose(value: object) -> Pose2D | None:
    """The pose an earlier run of this robot's fleet_member left on the parameter server (``~last_pose``:
    ``{x, y, yaw}`` in m and rad), or None when there is none or it is not such a mapping of finite
    numbers (a fresh site start: the robot is on its fleet-file start pose)."""
    if not isinstance(value, dict):
        return None
    try:
        x, y, yaw = (float(value[k]) for k in ("x", "y", "yaw"))
    except (KeyError, TypeError, ValueError):
        return None
    if not all(np.isfinite((x, y, yaw))):
        return None
    return Pose2D(x, y, yaw)


def pose_record(pose: Pose2D) -> dict:
    """``pose`` as fleet_member stores it under ``~last_pose`` (what :func:`saved_pose` reads back)."""
    return {"x": round(float(pose.x), 4), "y": round(float(pose.y), 4), "yaw": round(float(pose.yaw), 4)}


#: actionlib GoalStatus values of a goal still in the works (PENDING, ACTIVE, PREEMPTING, RECALLING)
GOAL_IN_WORK = frozenset((0, 1, 6, 7))


def remaining_path(points: np.ndarray, x: float, y: float, horizon: float) -> np.ndarray:
    """The part (K, 2) of a global plan ``points`` (M, 2) still ahead of a robot at (x, y): from the plan
    point nearest to it on, at most ``horizon`` m long (the point reaching it included).

    The nearest point is searched along the whole plan; a plan that passes the robot twice (a loop)
    is cut at the nearer pass."""
    ahead = from_nearest(points, x, y)
    if len(ahead) == 0 or horizon <= 0.0:
        return ahead[:0]
    cum = np.concatenate(([0.0], np.cumsum(np.hypot(*np.diff(ahead, axis=0).T))))
    return ahead[:int(np.searchsorted(cum, horizon, side="left")) + 1]


def state_text(goal_statuses: list[int], hold: str) -> str:
    """What a robot is doing, for people (RobotState.state): ``waiting: …`` while held with a goal in the
    works, ``driving`` with one, else ``idle``."""
    if not any(s in GOAL_IN_WORK for s in goal_statuses):
        return "idle"
    return f"waiting: {hold}" if hold else "driving"
