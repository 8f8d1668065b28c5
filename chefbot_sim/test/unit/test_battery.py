"""Battery discharge model and the board's battery line following it (firmware mode)."""
import math

import numpy as np
import pytest
from test_firmware_drive import EMPTY, Link, drive_with_commands

from chefbot_sim import battery
from chefbot_sim.battery import OCV_CURVES, BatteryConfig
from chefbot_sim.sim import SimConfigError, SimOptions, Simulator


@pytest.mark.parametrize("chem", sorted(OCV_CURVES))
def test_open_circuit_voltage_rises_with_charge(chem):
    cfg = BatteryConfig(chemistry=chem)
    v = [battery.open_circuit_voltage(cfg, s) for s in np.linspace(0, 1, 21)]
    assert all(b > a for a, b in zip(v, v[1:], strict=False))
    assert battery.open_circuit_voltage(cfg, -1.0) == v[0] and battery.open_circuit_voltage(cfg, 2.0) == v[-1]


def test_coulomb_counting_and_voltage_sag():
    cfg = BatteryConfig(capacity_ah=10.0, internal_resistance=0.05)
    assert battery.discharge(cfg, 1.0, 10.0, 360.0) == pytest.approx(0.9)      # 1 Ah of 10
    assert battery.discharge(cfg, 0.001, 10.0, 3600.0) == 0.0                  # never below empty
    assert battery.discharge(cfg, 0.5, -5.0, 360.0) == pytest.approx(0.55)     # charging: negative current
    assert battery.discharge(cfg, 0.99, -5.0, 3600.0) == 1.0                   # never above full
    rest = battery.terminal_voltage(cfg, 0.5, 0.0)
    assert battery.terminal_voltage(cfg, 0.5, 8.0) == pytest.approx(rest - 0.4)


def test_motor_current_follows_torque_and_brake_draws_nothing():
    cfg = BatteryConfig(motor_free_current=0.3, motor_stall_current=5.5)
    assert battery.motor_current(cfg, 0.0, -1.0, 2.0) == 0.0
    assert battery.motor_current(cfg, 0.5, 0.0, 2.0) == pytest.approx(0.3)
    assert battery.motor_current(cfg, 1.0, 2.0, 2.0) == pytest.approx(5.5)
    assert battery.motor_current(cfg, -1.0, -1.0, 2.0) == pytest.approx(0.3 + 5.2 / 2)


@pytest.mark.parametrize("field,value", [("battery_chemistry", "lead"), ("battery_capacity_ah", 0.0),
                                         ("battery_initial_soc", 1.5), ("battery_idle_current", math.nan)])
def test_bad_battery_params_are_named(urdf, field, value):
    with pytest.raises(SimConfigError, match=field):
        Simulator(urdf, EMPTY, options=SimOptions(**{field: value}))


def battery_lines(lines) -> list[float]:
    return [float(f[1]) for f in lines if f[0] == "b"]


def test_board_battery_line_follows_the_discharge(urdf, tmp_path):
    # a tiny pack so seconds of sim time discharge it visibly
    opts = SimOptions(seed=1, drive="firmware", pty_link=str(tmp_path / "lp"), battery_capacity_ah=0.01,
                      battery_initial_soc=0.8)
    sim = Simulator(urdf, EMPTY, options=opts)
    link = Link(str(tmp_path / "lp"))
    try:
        idle = drive_with_commands(sim, link, 0, 0, 4.0)
        soc_idle, amps_idle = sim.battery
        assert amps_idle == pytest.approx(2.5)                            # idle draw only, braked motors
        assert soc_idle == pytest.approx(0.8 - 2.5 * 4.0 / 36.0, abs=0.005)
        driving = drive_with_commands(sim, link, 800, 800, 4.0)
        soc_drive, amps_drive = sim.battery
        assert amps_drive > 2.5 + 2 * 0.3                                 # the motors draw too
        assert soc_idle - soc_drive > 2.5 * 4.0 / 36.0
        volts = battery_lines(idle) + battery_lines(driving)
        assert len(volts) >= 4 and volts[-1] < volts[0] - 0.1            # the board's `b` line falls
        cfg = opts.battery_config()
        assert volts[-1] == pytest.approx(battery.terminal_voltage(cfg, soc_drive, amps_drive), abs=0.1)
    finally:
        link.close()
        sim.close()


def test_constant_voltage_without_the_model(urdf, tmp_path):
    opts = SimOptions(seed=1, drive="firmware", pty_link=str(tmp_path / "lp"), battery_model=False,
                      battery_volts=11.7)
    sim = Simulator(urdf, EMPTY, options=opts)
    link = Link(str(tmp_path / "lp"))
    try:
        volts = battery_lines(drive_with_commands(sim, link, 800, 800, 3.0))
        assert volts and all(v == pytest.approx(11.7, abs=0.01) for v in volts)
    finally:
        link.close()
        sim.close()
