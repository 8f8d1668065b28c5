"""What one robot of a fleet knows about itself from the site's fleet file (pure, no rospy)."""
from __future__ import annotations

from chefbot_common.fleet_file import FleetFileError, FleetRobot, load_fleet

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
