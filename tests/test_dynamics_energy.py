"""Energy (uavxai.dynamics.energy, issue 12): the uav_fw's motor power from JSBSim, the battery
data of its package, and the state of charge integrated from them.
"""

from __future__ import annotations

import math

import jsbsim
import numpy as np
import pytest

from uavxai.dynamics.aircraft import Aircraft
from uavxai.dynamics.energy import J_PER_WH, Battery, BatterySpec
from uavxai.dynamics.fdm import load_fdm
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.orbit import OrbitGuidance, radius_for
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.units import FT

DT = 1.0 / 120.0
SAMPLE_TICKS = 12  # the episode's 10 Hz sample rate
LBF = 4.4482216  # N per pound-force


def started(speed_mps: float = 20.0) -> Aircraft:
    frame = LocalFrame.from_origin(default_scenario("energy-test").world.origin)
    a = Aircraft("uav_fw", frame, DT, seed=1)
    a.set_limits(bank_limit_rad=math.radians(30))
    assert a.start(0.0, 0.0, 120.0, 0.0, speed_mps)
    return a


# ------------------------------------------------------------------- the package's data
def test_battery_data_comes_from_the_aircraft_package() -> None:
    spec = BatterySpec.from_fdm(load_fdm("uav_fw", DT), "uav_fw")
    # aircraft/uav_fw/Systems/uav_fw_battery.xml: 6S 10 Ah, 20 % reserve, 85 % motor + ESC
    assert spec.capacity_wh == pytest.approx(222.0)
    assert spec.reserve_soc == pytest.approx(0.20)
    assert spec.motor_efficiency == pytest.approx(0.85)
    assert spec.constant_load_w == pytest.approx(25.0)
    assert spec.usable_wh == pytest.approx(222.0 * 0.8)
    assert spec.voltage_v == pytest.approx(22.2)  # 6S nominal: 222 Wh = 10 Ah
    assert spec.current_a(222.0) == pytest.approx(10.0)


def test_an_aircraft_without_battery_data_is_a_user_error() -> None:
    bare = jsbsim.FGFDMExec(None)  # no model: no electric/* properties
    with pytest.raises(UserError, match="electric/battery-capacity-wh"):
        BatterySpec.from_fdm(bare, "bare")


@pytest.mark.parametrize(
    ("kwargs", "field"),
    [
        ({"capacity_wh": 0.0}, "capacity_wh"),
        ({"capacity_wh": 100.0, "reserve_soc": 1.0}, "reserve_soc"),
        ({"capacity_wh": 100.0, "soc": 1.5}, "soc"),
    ],
)
def test_battery_rejects_bad_input(kwargs: dict, field: str) -> None:
    with pytest.raises(UserError, match=field):
        Battery(**kwargs)
    with pytest.raises(UserError, match="dt"):
        Battery(100.0).draw(10.0, -1.0)


# ------------------------------------------------------------------------- the battery
def test_soc_falls_to_the_reserve_at_the_expected_time_at_constant_power() -> None:
    b = Battery(capacity_wh=222.0, reserve_soc=0.2)
    power, dt = 300.0, 1.0
    expected_s = 0.8 * 222.0 * J_PER_WH / power  # 2131.2 s
    assert b.time_to_reserve_s(power) == pytest.approx(expected_s)
    socs, t = [b.soc], 0.0
    while not b.at_reserve:
        b.draw(power, dt)
        t += dt
        socs.append(b.soc)
        assert t < 2 * expected_s
    assert t == pytest.approx(expected_s, abs=dt)
    assert np.all(np.diff(socs) < 0)
    assert b.energy_wh == pytest.approx(power * t / J_PER_WH)
    # It goes on to empty and stops there.
    for _ in range(3000):
        b.draw(power, dt)
    assert b.empty and b.soc == 0.0


def test_draw_integrates_with_the_trapezoid_rule() -> None:
    b = Battery(100.0)
    b.draw(100.0, 0.0)  # the first sample, nothing drawn yet
    b.draw(300.0, 36.0)  # a ramp 100 -> 300 W over 36 s: 7200 J = 2 Wh
    assert b.energy_wh == pytest.approx(2.0)
    assert b.soc == pytest.approx(0.98)


# -------------------------------------------------------------------- JSBSim's motor power
def test_cruise_power_is_plausible_for_a_small_electric_fixed_wing() -> None:
    a = started(20.0)
    try:
        for _ in range(round(10 / DT)):  # settle
            a.run()
        shaft, motor, throttle, thrust_power = [], [], [], []
        for _ in range(round(10 / DT)):
            a.run()
            shaft.append(a.shaft_power_w())
            motor.append(a.motor_power_w())
            throttle.append(a.throttle())
            thrust_power.append(a.fdm["propulsion/engine/thrust-lbs"] * LBF * a.raw_state()[9] * FT)
        spec = a.battery_spec()
        total = a.electric_power_w()
    finally:
        a.close()
    shaft, motor, throttle = np.array(shaft), np.array(motor), np.array(throttle)
    # The electric engine: shaft power = throttle x its 1000 W rating.
    np.testing.assert_allclose(shaft, throttle * 1000.0, rtol=1e-9)
    np.testing.assert_allclose(motor, shaft / 0.85, rtol=1e-12)
    assert 0.0 < throttle.mean() < 1.0
    # Measured 288 W at 20 m/s: a 9 kg aircraft with L/D about 9.
    assert 50.0 < motor.mean() < 400.0
    # The propeller turns the shaft power into thrust x airspeed at a plausible efficiency.
    eta = np.mean(thrust_power) / shaft.mean()
    assert 0.6 < eta < 0.85
    assert total == pytest.approx(motor[-1] + spec.constant_load_w)
    # Endurance from full to the reserve at cruise: measured 34 min.
    assert 20 * 60 < spec.endurance_s(total) < 60 * 60


def test_throttle_follows_the_speed_command() -> None:
    a = started(16.0)
    try:
        for _ in range(round(2 / DT)):
            a.run()
        before = a.throttle()
        a.command(accel_cmd_mps2=1.0)
        for _ in range(round(5 / DT)):
            a.run()
        after = a.throttle()
    finally:
        a.close()
    assert 0.0 <= before < after <= 1.0
    assert after - before > 0.1


def test_energy_is_the_integral_of_the_motor_power_jsbsim_reports() -> None:
    """A battery drawn at the 10 Hz samples against the trapezoid of JSBSim's motor power at
    every 120 Hz integration step, over a flight that varies the power a lot: a climb, a
    speed-up and an orbit with its capture."""
    a = started(18.0)
    r = radius_for(22.0, math.radians(30))
    g = OrbitGuidance((300.0, 300.0), r, bank_limit_rad=math.radians(30))
    battery = Battery.from_spec(a.battery_spec())
    try:
        fine = [a.motor_power_w()]
        battery.draw(fine[0], 0.0)
        samples = [fine[0]]
        a.command(alt_target_m=160.0, speed_target_mps=22.0)
        for _ in range(round(120 / (DT * SAMPLE_TICKS))):
            lat, lon, _, ve, vn, _, _, _, _, vt = a.raw_state()
            x, y, _ = a.frame.to_local(lat, lon, 0.0)
            a.command(bank_cmd_rad=g.bank_command((x, y), (ve * FT, vn * FT), vt * FT))
            for _ in range(SAMPLE_TICKS):
                a.run()
                fine.append(a.motor_power_w())
            samples.append(fine[-1])
            battery.draw(samples[-1], SAMPLE_TICKS * DT)
    finally:
        a.close()
    fine = np.array(fine)
    reference_wh = float(np.sum(0.5 * (fine[1:] + fine[:-1])) * DT / J_PER_WH)
    assert fine.max() > 1.5 * fine.min()  # the power did vary
    assert battery.energy_wh == pytest.approx(reference_wh, rel=0.005)
    # ... and it is exactly the trapezoid of the samples it was given.
    sampled_wh = float(np.trapezoid(samples, dx=SAMPLE_TICKS * DT) / J_PER_WH)
    assert battery.energy_wh == pytest.approx(sampled_wh, rel=1e-12)
    assert battery.soc == pytest.approx(1 - reference_wh / 222.0, rel=1e-4)


def test_the_reported_voltage_falls_with_the_charge_and_sags_under_load() -> None:
    """SYS_STATUS voltage_battery: a 6S LiPo (22.2 V nominal) reads 25.2 V full, about 22.9 V
    half-empty, and lower under load; a package without a voltage reports 0 (unknown)."""
    spec = BatterySpec(capacity_wh=222.0, reserve_soc=0.2, voltage_v=22.2)
    full, half, low = (spec.terminal_voltage_v(s, 0.0) for s in (1.0, 0.5, 0.05))
    assert full == pytest.approx(6 * 4.20) and half == pytest.approx(6 * 3.82)
    assert full > half > low > 6 * 3.5
    assert spec.terminal_voltage_v(0.5, 20.0) == pytest.approx(half - 6 * 0.004 * 20.0)
    assert BatterySpec(capacity_wh=100.0, reserve_soc=0.2).terminal_voltage_v(0.5, 5.0) == 0.0
