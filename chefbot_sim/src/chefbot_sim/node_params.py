"""chefbot_sim_node's parameters (pure): its own settings and the Simulator's options, read once.

Defaults and units: ``param/sim.yaml`` and the package README.
"""
from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from chefbot_common.params import ParamError, private_spec, read_config
from chefbot_sim.sim import SimConfigError, SimOptions

DEFAULT_FIRMWARE_MAX_RTF = 0.0   # no cap; see the package README, "Firmware in the loop"
STEPS_PER_BATCH = 12  # physics steps between checks of requests/pacing (0.05 s of sim time)
# Firmware mode paces every physics step (4.2 ms) and never catches up in a burst:
# launchpad_node checks encoder lines for impossible jumps against WALL time.
FIRMWARE_STEPS_PER_BATCH = 1
FIRMWARE_MAX_LAG = 0.02  # s of wall time behind schedule before the pacer restarts from now


@dataclass(frozen=True)
class SimNodeParams:
    """The node's own params: world file, start pose (m, m, rad), pacing, frames."""

    robot_description: str = field(default="", repr=False)  # URDF (global param, with its <chefbot_sim> block)
    world: str = ""                   # path of a world file (YAML or SDF)
    x: float = 0.0                    # [m] start x of the robot in the world (finite)
    y: float = 0.0                    # [m] start y of the robot in the world (finite)
    yaw: float = 0.0                  # [rad] start heading in the world (0: facing +x; finite)
    real_time_factor: float = 1.0     # sim s per wall s (0 = as fast as possible)
    firmware_max_rtf: float = DEFAULT_FIRMWARE_MAX_RTF  # firmware mode's cap on the above (0 = none)
    publish_tf: bool = True           # odom -> base tf (plugin drive only)
    world_frame: str = "map"          # frame of ground_truth/odom
    gui: bool = False                 # pybullet's own window
    fleet_file: str = ""              # several robots in this world: the site's fleet file (chefbot_common.fleet_file;
                                      # '' = one robot, as above); then x, y, yaw and robot_description are
                                      # unused: each robot starts at its fleet-file start pose, with the model
                                      # <name>/robot_description, and its topics are under /<name>
    robots: int = 1                   # with fleet_file: how many of its robots (its first N; >= 1)
    cmd_vel_topic: str = "cmd_vel"    # with fleet_file: each robot's velocity command topic, relative to its
                                      # namespace (cmd_vel_guarded behind chefbot_bringup's cliff guard)
    model_timeout: float = 120.0      # [s] with fleet_file: wall time to wait for every robot's
                                      # <name>/robot_description (its stack, perhaps on its own PC, started after
                                      # the world); then the node ends naming the missing ones (>= 0)

    def __post_init__(self) -> None:
        if not self.fleet_file and not self.robot_description:
            raise ValueError("robot_description is not set (include chefbot_description's robot_state.launch.xml)")
        if self.robots < 1:
            raise ValueError(f"robots must be >= 1, got {self.robots}")
        if not (math.isfinite(self.model_timeout) and self.model_timeout >= 0):
            raise ValueError(f"model_timeout must be >= 0 s, got {self.model_timeout}")
        if not self.cmd_vel_topic or self.cmd_vel_topic.startswith("/"):
            raise ValueError(f"cmd_vel_topic must be a relative topic name, got {self.cmd_vel_topic!r}")
        if not self.world:
            raise ValueError("world (path of a world file) is not set")
        if not all(math.isfinite(v) for v in (self.x, self.y, self.yaw)):
            raise ValueError(f"x, y and yaw must be finite, got ({self.x}, {self.y}, {self.yaw})")
        if not (math.isfinite(self.real_time_factor) and self.real_time_factor >= 0):
            raise ValueError(f"real_time_factor must be >= 0 (0 = as fast as possible), got {self.real_time_factor}")
        if not self.firmware_max_rtf >= 0:
            raise ValueError(f"firmware_max_rtf must be >= 0 (0 = no cap), got {self.firmware_max_rtf}")
        if not self.world_frame:
            raise ValueError("world_frame must be a non-empty frame name")

    def effective_rtf(self, firmware: bool) -> float:
        """Real-time factor to run at: firmware mode is held to ``firmware_max_rtf`` (its driver, PID
        and watchdog chain runs on real-time timers)."""
        cap = self.firmware_max_rtf
        if firmware and cap > 0 and (self.real_time_factor <= 0 or self.real_time_factor > cap):
            return cap
        return self.real_time_factor


@dataclass(frozen=True)
class CliffTopicsParams:
    """Where each cliff sensor publishes (checked against the robot's sensors by :func:`cliff_topics`)."""

    cliff_topics: dict = field(default_factory=dict)   # URDF cliff sensor name -> relative Range topic
                                                       #   (a sensor not listed: cliff/<name without cliff_>)


@dataclass(frozen=True)
class RobotOptionsParams:
    """Per-robot simulator options of a fleet (checked by :func:`member_options`)."""

    robot_options: dict = field(default_factory=dict)  # with fleet_file: robot name -> {option: value}, that
                                                       #   robot's simulator options over the ones above (e.g.
                                                       #   {chefbot2: {battery_initial_soc: 0.6}}; not time_step
                                                       #   or solver_iterations, which the world shares)


# what chefbot_sim_node reads (its PARAMS): the node's own params, the Simulator's options (every
# SimOptions field but time_step) and the cliff topics, as ``~name``; robot_description relative
SIM_NODE = private_spec(SimNodeParams, robot_description="robot_description")
SIM_OPTIONS = private_spec(SimOptions, skip=("time_step",))
CLIFF_TOPICS = private_spec(CliffTopicsParams)
ROBOT_OPTIONS = private_spec(RobotOptionsParams)
SHARED_OPTIONS = ("time_step", "solver_iterations")   # one world steps every robot alike


def read_sim_params(get: Callable[[str, Any], Any]) -> tuple[SimNodeParams, SimOptions]:
    """The node's params (:data:`SIM_NODE`) and the Simulator's options (:data:`SIM_OPTIONS`)."""
    node = SIM_NODE.read(get)
    opts = SIM_OPTIONS.read(get)
    opts.validate()
    return node, opts


def cliff_topics(sensors: list[str], mapping: Any) -> list[str]:
    """Topic of each cliff sensor (URDF ``<cliff name=...>``) from ``~cliff_topics`` (sensor name -> topic).

    A sensor missing from the mapping publishes on ``cliff/<name without 'cliff_'>``; topics are
    relative so they follow the node's namespace.  ParamError names a bad entry.
    """
    if mapping is None:
        mapping = {}
    if not isinstance(mapping, dict):
        raise ParamError(f"parameter ~cliff_topics must be a map sensor name -> topic, got {mapping!r}")
    unknown = sorted(set(mapping) - set(sensors))
    if unknown:
        raise ParamError(f"parameter ~cliff_topics names {', '.join(map(str, unknown))}, but the robot's cliff "
                         f"sensors are {', '.join(sensors)}")
    topics = []
    for name in sensors:
        topic = mapping.get(name, "cliff/" + name.removeprefix("cliff_"))
        if not isinstance(topic, str) or not topic or topic.startswith("/"):
            raise ParamError(f"parameter ~cliff_topics/{name} must be a non-empty relative topic name, got {topic!r}")
        topics.append(topic)
    if len(set(topics)) != len(topics):
        raise ParamError(f"parameter ~cliff_topics maps two sensors to one topic: {topics}")
    return topics


def pacing(firmware: bool, rtf: float) -> tuple[int, float | None]:
    """Physics steps per loop turn and the pacer's ``max_lag`` (s) for a drive mode and real-time factor."""
    if firmware:
        return (FIRMWARE_STEPS_PER_BATCH if rtf > 0 else STEPS_PER_BATCH), FIRMWARE_MAX_LAG
    return STEPS_PER_BATCH, None


@dataclass(frozen=True)
class FleetMember:
    """One robot of a simulated fleet: its name (namespace), model, start and charger poses (world frame)."""

    name: str
    robot_description: str = field(repr=False)
    start: tuple[float, float, float]
    charger: tuple[float, float, float] | None = None


def fleet_robots(node: SimNodeParams) -> list:
    """The robots of ``~fleet_file`` the sim holds (its first ``~robots``; chefbot_common.fleet_file's
    FleetRobot).  ParamError (a ValueError) names a bad file."""
    from chefbot_common.fleet_file import FleetFileError, load_fleet, select

    try:
        return select(load_fleet(node.fleet_file), node.robots, node.fleet_file)
    except FleetFileError as e:
        raise ParamError(f"parameter ~fleet_file: {e}") from None


def missing_models(node: SimNodeParams, get: Callable[[str, Any], Any]) -> list[str]:
    """The names of the fleet's robots whose ``<name>/robot_description`` is not set yet."""
    return [r.name for r in fleet_robots(node) if not get(f"{r.name}/robot_description", "")]


def fleet_members(node: SimNodeParams, get: Callable[[str, Any], Any]) -> list[FleetMember]:
    """The robots of ``~fleet_file`` the sim holds (its first ``~robots``), each with its model from
    ``<name>/robot_description``.  ParamError (a ValueError) names a missing model or a bad file."""
    out = []
    for r in fleet_robots(node):
        urdf = get(f"{r.name}/robot_description", "")
        if not urdf:
            raise ParamError(f"{r.name}/robot_description is not set: start the robot's stack (chefbot_sim "
                             f"fleet_robot.launch robot:={r.name}, or chefbot_description's "
                             f"robot_state.launch.xml with frame_prefix '{r.name}/' in namespace {r.name})")
        charger = (r.charger.x, r.charger.y, r.charger.yaw) if r.charger is not None else None
        out.append(FleetMember(r.name, urdf, (r.start.x, r.start.y, r.start.yaw), charger))
    return out


def check_robot_options(mapping: Any, names: list[str]) -> dict[str, dict]:
    """``~robot_options`` checked against the fleet's robot names: a map name -> map of options.
    ParamError names an unknown robot or a value that is not a map."""
    if mapping is None:
        return {}
    if not isinstance(mapping, dict):
        raise ParamError(f"parameter ~robot_options must be a map robot name -> {{option: value}}, got {mapping!r}")
    unknown = sorted(map(str, set(mapping) - set(names)))
    if unknown:
        raise ParamError(f"parameter ~robot_options names {', '.join(unknown)}, but the sim holds "
                         f"{', '.join(names)}")
    for robot, over in mapping.items():
        if not isinstance(over, dict):
            raise ParamError(f"parameter ~robot_options/{robot} must be a map option -> value, got {over!r}")
    return dict(mapping)


def member_options(opts: SimOptions, index: int, name: str, overrides: dict | None = None) -> SimOptions:
    """Robot ``index`` (named ``name``) of a fleet gets the sim's options with its own noise seed
    (seed + index), its own LaunchPad pty link (pty_link + '_' + name) and its lidar frame under
    its tf prefix ('<name>/laser' unless lidar_frame names a prefix already), then ``overrides``
    (its entry of ``~robot_options``: SimOptions fields; an option given there wins, seed included).
    ParamError names an unknown, shared or bad option."""
    from dataclasses import fields, replace
    lidar_frame = opts.lidar_frame if "/" in opts.lidar_frame else f"{name}/{opts.lidar_frame}"
    base = replace(opts, seed=opts.seed + index, pty_link=f"{opts.pty_link}_{name}" if opts.pty_link else "",
                   lidar_frame=lidar_frame)
    over = dict(overrides or {})
    if not over:
        return base
    prefix = f"~robot_options/{name}/"
    known = {f.name for f in fields(SimOptions)}
    bad = sorted(map(str, set(over) - (known - set(SHARED_OPTIONS))))
    if bad:
        raise ParamError(f"parameter {prefix}{bad[0]}: not a per-robot simulator option "
                         + ("(the world steps every robot alike)" if bad[0] in SHARED_OPTIONS
                            else "(see the node's simulator options)"))
    fixed = {k: getattr(base, k) for k in known if k not in over}
    out = read_config(SimOptions, lambda p, d: over.get(p.removeprefix(prefix), d), {k: prefix + k for k in over},
                      **fixed)
    try:
        out.validate()
    except SimConfigError as exc:
        raise ParamError(f"parameter {prefix[:-1]}: {exc}") from None
    return out
