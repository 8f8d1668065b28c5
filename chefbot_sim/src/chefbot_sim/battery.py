"""Battery discharge of the simulated ChefBot (firmware mode feeds it to the board's `b` line).

The book's robot runs on a 12 V 10 Ah pack (SLA or LiPo) feeding the NUC
(12 V, up to 5 A), the Kinect/Astra (12 V, 1 A) and two 12 V gear motors; it
is meant to run about 2 h.  Model:

* current I = ``idle_current`` (PC + camera + board, A) + per motor
  ``free_current + (stall_current - free_current) * |tau| / stall_torque``
  while its duty is not 0 (a DC motor's current follows its torque; the
  torque comes from :class:`chefbot_sim.firmware_drive.DcMotor` at the
  firmware's duty and the wheel's speed), 0 for a braked motor;
* state of charge falls by I dt / capacity (coulomb counting);
* terminal voltage = open-circuit voltage(state of charge) - I x
  ``internal_resistance``; the open-circuit curve is tabulated per chemistry
  (12 V SLA, 3S LiPo, 10-cell NiMH) and interpolated linearly.

Pure (no pybullet, no rospy); the state of charge lives in the simulator's
snapshot state.
"""
from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

# open-circuit voltage (V) at state of charge 0, 0.1, ..., 1.0 (typical datasheet curves, rested)
OCV_CURVES: dict[str, tuple[float, ...]] = {
    # 12 V sealed lead-acid (6 cells): 11.6 V flat ... 12.7 V full
    "sla": (11.6, 11.75, 11.9, 12.0, 12.1, 12.2, 12.3, 12.4, 12.5, 12.6, 12.7),
    # 3S LiPo: 3.3 ... 4.2 V per cell, the knee below 10 %
    "lipo3s": (9.9, 10.8, 11.1, 11.25, 11.4, 11.5, 11.6, 11.75, 11.9, 12.15, 12.6),
    # 10-cell NiMH: 1.0 ... 1.4 V per cell, flat middle
    "nimh10": (10.0, 11.6, 11.9, 12.0, 12.1, 12.2, 12.25, 12.3, 12.4, 12.6, 14.0),
}
_SOC_GRID = np.linspace(0.0, 1.0, 11)


@dataclass(frozen=True)
class BatteryConfig:
    """The pack and what draws from it (V, A, Ah, ohm)."""

    chemistry: str = "sla"             # sla | lipo3s | nimh10
    capacity_ah: float = 10.0          # Ah (book: 10 Ah)
    initial_soc: float = 0.9           # state of charge at start, 0..1
    internal_resistance: float = 0.05  # ohm, pack + wiring
    idle_current: float = 2.5          # A: NUC ~1.5 A + camera ~0.5 A + board/sensors at 12 V
    motor_free_current: float = 0.3    # A per motor turning unloaded (Pololu 37D 12 V)
    motor_stall_current: float = 5.5   # A per motor at stall torque (Pololu 37D 12 V)

    def __post_init__(self) -> None:
        if self.chemistry not in OCV_CURVES:
            raise ValueError(f"battery_chemistry must be one of {', '.join(OCV_CURVES)}, got {self.chemistry!r}")
        for name in ("capacity_ah", "internal_resistance", "idle_current", "motor_free_current",
                     "motor_stall_current"):
            v = getattr(self, name)
            if not (math.isfinite(v) and v >= 0):
                raise ValueError(f"battery_{name} must be a finite number >= 0, got {v!r}")
        if self.capacity_ah <= 0:
            raise ValueError(f"battery_capacity_ah must be > 0, got {self.capacity_ah!r}")
        if not 0.0 <= self.initial_soc <= 1.0:
            raise ValueError(f"battery_initial_soc must be within 0..1, got {self.initial_soc!r}")


def motor_current(cfg: BatteryConfig, duty: float, torque: float, stall_torque: float) -> float:
    """Current (A) of one motor at ``duty`` (-1..1) giving ``torque`` (N·m at the wheel)."""
    if duty == 0.0:
        return 0.0   # brake: the H-bridge shorts the motor, nothing from the battery
    share = min(abs(torque) / stall_torque, 1.0) if stall_torque > 0 else 0.0
    return cfg.motor_free_current + (cfg.motor_stall_current - cfg.motor_free_current) * share


def open_circuit_voltage(cfg: BatteryConfig, soc: float) -> float:
    """Rested pack voltage (V) at state of charge ``soc`` (0..1, clipped)."""
    return float(np.interp(min(max(soc, 0.0), 1.0), _SOC_GRID, OCV_CURVES[cfg.chemistry]))


def discharge(cfg: BatteryConfig, soc: float, current: float, dt: float) -> float:
    """State of charge after drawing ``current`` A for ``dt`` s (negative: charging), within 0..1."""
    return min(max(soc - current * dt / (cfg.capacity_ah * 3600.0), 0.0), 1.0)


def terminal_voltage(cfg: BatteryConfig, soc: float, current: float) -> float:
    """Voltage (V) the board measures: open-circuit minus the drop over the internal resistance."""
    return max(open_circuit_voltage(cfg, soc) - current * cfg.internal_resistance, 0.0)
