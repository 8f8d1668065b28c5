"""Several ChefBots in one pybullet world (no ROS).

A :class:`Fleet` owns one :class:`chefbot_sim.bullet.BulletSim` with the world's shapes and
one :class:`chefbot_sim.sim.Simulator` per robot living in it (``shared``): one physics step
moves every robot, so robots push each other as bodies do, and each robot's sensors (depth
camera, sonar, lidar, cliff sensors, RGB) see the other robots' bodies, never their own; a
robot touching another one reads it as a bumper contact naming that robot.

Every robot keeps its own drive (plugin or firmware), odometry, noise streams and sensor
schedule; all of them share one clock (the fleet's sim time).
"""
from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass

from chefbot_common.geometry import Pose2D
from chefbot_sim.bullet import BulletSim
from chefbot_sim.events import Event
from chefbot_sim.sim import SimConfigError, SimOptions, Simulator
from chefbot_sim.world import Shape, World


@dataclass(frozen=True)
class RobotSpec:
    """One robot of a fleet: its name (the ROS namespace, e.g. ``chefbot1``), robot description
    (URDF with the ``<chefbot_sim>`` block, frames as its stack names them), start pose in the
    world frame and simulator options (drive, noise seed, lidar, ...)."""

    name: str
    urdf_xml: str
    start: Pose2D
    options: SimOptions
    charger: Pose2D | None = None      # where it charges (the fleet file's charger pose)


class Fleet:
    """Robots in one world, stepped together.  ``robots`` needs at least one entry; names must
    be unique and the start poses must not put two bodies into each other (SimConfigError names
    the pair).  All robots must use the same physics time step and solver iterations."""

    def __init__(self, world: World, robots: Sequence[RobotSpec], gui: bool = False) -> None:
        if not robots:
            raise SimConfigError("a fleet needs at least one robot")
        names = [r.name for r in robots]
        if len(set(names)) != len(names) or not all(names):
            raise SimConfigError(f"robot names must be unique and non-empty, got {names}")
        steps = {(r.options.time_step, r.options.solver_iterations) for r in robots}
        if len(steps) != 1:
            raise SimConfigError("every robot of a fleet needs the same time_step and solver_iterations")
        step, iterations = steps.pop()
        self.world = world
        self.bullet = BulletSim(gui=gui, time_step=step, solver_iterations=iterations)
        self.sims: list[Simulator] = []
        try:
            self.bullet.load_world(world)
            for r in robots:
                self.sims.append(Simulator(r.urdf_xml, world, r.start, r.options, shared=self.bullet, name=r.name))
                self.sims[-1].charger = r.charger
            self._check_apart()
        except BaseException:
            self.close()
            raise
        self.names = names
        for sim in self.sims[1:]:   # one clock: the first robot's
            sim.set_enabled("clock", False)
        self._spawned: list[str] = []

    def _check_apart(self) -> None:
        bodies = [s.body for s in self.sims]
        for i, a in enumerate(bodies):
            for b in bodies[i + 1:]:
                if a.touches(b):
                    pa, pb = (self.sims[k].start for k in (a.index, b.index))
                    raise SimConfigError(f"robots '{a.name}' and '{b.name}' start {pa.distance(pb):.2f} m "
                                         "apart: their bodies overlap (give them start poses further apart)")

    # ------------------------------------------------------------ access
    @property
    def time(self) -> float:
        """Sim time in s (every robot's)."""
        return self.sims[0].time

    def robot(self, name: str) -> Simulator:
        """The robot ``name`` (KeyError names the known ones)."""
        for n, sim in zip(self.names, self.sims, strict=True):
            if n == name:
                return sim
        raise KeyError(f"no robot '{name}' (robots: {', '.join(self.names)})")

    # ------------------------------------------------------------ stepping
    def step(self, n: int = 1) -> list[tuple[int, Event]]:
        """Advance ``n`` physics steps; return (robot index, reading) for every reading due."""
        events: list[tuple[int, Event]] = []
        sims = self.sims
        step = self.bullet.step
        buf: list[Event] = []
        for _ in range(n):
            for sim in sims:
                sim.before_physics()
            step()
            for i, sim in enumerate(sims):
                sim.after_physics(buf)
                if buf:
                    events.extend((i, e) for e in buf)
                    buf.clear()
        return events

    def run(self, duration: float) -> list[tuple[int, Event]]:
        """Advance by ``duration`` s of sim time; returns the readings as :meth:`step` does."""
        return self.step(int(round(duration / self.bullet.time_step)))

    # ------------------------------------------------------------ world edits
    def spawn(self, shape: Shape) -> None:
        """Add a static obstacle every robot sees (its name must be new)."""
        self.sims[0].spawn(shape)
        for sim in self.sims[1:]:
            sim.spawn(shape, add_body=False)
        self._spawned.append(shape.name)

    def remove(self, name: str) -> None:
        """Remove a spawned obstacle."""
        self.sims[0].remove(name)
        for sim in self.sims[1:]:
            sim.remove(name, remove_body=False)
        self._spawned.remove(name)

    def reset(self) -> None:
        """Every robot back to its start pose at rest, spawned obstacles removed, odometry zeroed;
        sim time runs on."""
        for name in list(self._spawned):
            self.remove(name)
        for sim in self.sims:
            sim.reset()

    def close(self) -> None:
        """Free every robot (firmware ptys) and pybullet."""
        for sim in self.sims:
            sim.close()
        self.bullet.close()
