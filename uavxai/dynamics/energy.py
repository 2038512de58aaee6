"""Electrical energy: the battery the motor and the payload draw from.

JSBSim's ``electric_engine`` is an ideal motor: its shaft power is the throttle times its
rating (``propulsion/engine/power-hp``). The electrical power it takes from the battery is that
over the motor and ESC efficiency; the avionics and the base-station payload add constant
loads. The figures (capacity, reserve, efficiency, loads) are data of the aircraft package,
``aircraft/<name>/Systems/<name>_battery.xml`` (see ``aircraft/uav_fw/README.md``), read by
:meth:`BatterySpec.from_fdm`; :class:`Battery` integrates a load into energy used and a
state of charge.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uavxai.errors import UserError

WATTS_PER_HP = 745.7  # JSBSim's hptowatts (FGJSBBase), so that W -> hp -> W is exact
J_PER_WH = 3600.0

# The aircraft package's battery data (declared in its Systems/*_battery.xml)
CAPACITY_WH = "electric/battery-capacity-wh"
RESERVE_SOC = "electric/battery-reserve-soc"
VOLTAGE_V = "electric/battery-voltage-v"
MOTOR_EFFICIENCY = "electric/motor-efficiency"
AVIONICS_POWER_W = "electric/avionics-power-w"
PAYLOAD_POWER_W = "electric/payload-power-w"
# What JSBSim computes
SHAFT_POWER_HP = "propulsion/engine/power-hp"  # FGElectric: throttle x rated power
THROTTLE = "fcs/throttle-pos-norm"  # the motor's throttle, 0..1, after the servo mixer

# A lithium polymer cell's open-circuit voltage against its state of charge (a typical
# discharge curve of a LiPo cell at low rate: flat near 3.8 V, falling steeply below 10 %).
LIPO_OCV = (
    (0.0, 3.27), (0.05, 3.61), (0.1, 3.69), (0.2, 3.73), (0.3, 3.77), (0.4, 3.79),
    (0.5, 3.82), (0.6, 3.87), (0.7, 3.92), (0.8, 3.98), (0.9, 4.06), (1.0, 4.20),
)  # fmt: skip
LIPO_NOMINAL_CELL_V = 3.7
CELL_RESISTANCE_OHM = 0.004  # per cell, a 10 Ah pack: a 20 A load sags 6S by about 0.5 V


@dataclass(frozen=True)
class BatterySpec:
    """An aircraft's battery and electrical loads."""

    capacity_wh: float
    reserve_soc: float
    motor_efficiency: float = 1.0
    avionics_power_w: float = 0.0
    payload_power_w: float = 0.0
    voltage_v: float = 0.0  # nominal; 0: not given

    def __post_init__(self) -> None:
        _check_capacity(self.capacity_wh)
        _check_reserve(self.reserve_soc)
        if not (math.isfinite(self.motor_efficiency) and 0 < self.motor_efficiency <= 1):
            raise UserError(
                f"battery motor_efficiency must be in (0, 1], got {self.motor_efficiency}"
            )
        for name in ("avionics_power_w", "payload_power_w", "voltage_v"):
            value = getattr(self, name)
            if not (math.isfinite(value) and value >= 0):
                raise UserError(f"battery {name} must be a finite number >= 0, got {value}")

    @property
    def constant_load_w(self) -> float:
        """Avionics plus payload, W: drawn whatever the motor does."""
        return self.avionics_power_w + self.payload_power_w

    @property
    def usable_wh(self) -> float:
        """Energy that may be drawn before the reserve, Wh."""
        return self.capacity_wh * (1.0 - self.reserve_soc)

    def current_a(self, power_w: float) -> float:
        """The battery current for a load of ``power_w`` at the nominal voltage (MAVLink
        SYS_STATUS ``current_battery``); 0 when the package gives no voltage."""
        return power_w / self.voltage_v if self.voltage_v > 0 else 0.0

    def terminal_voltage_v(self, soc: float, current_a: float) -> float:
        """The pack's voltage under load (MAVLink SYS_STATUS ``voltage_battery``): a lithium
        polymer cell's open-circuit voltage at this state of charge (:data:`LIPO_OCV`), times
        the cells the nominal voltage implies (3.7 V each), less the sag of the load on the
        pack's internal resistance (:data:`CELL_RESISTANCE_OHM` per cell); 0 when the package
        gives no voltage."""
        if self.voltage_v <= 0:
            return 0.0
        cells = max(1, round(self.voltage_v / LIPO_NOMINAL_CELL_V))
        ocv = float(np.interp(min(max(soc, 0.0), 1.0), *zip(*LIPO_OCV, strict=True)))
        return max(0.0, cells * (ocv - max(current_a, 0.0) * CELL_RESISTANCE_OHM))

    def endurance_s(self, power_w: float) -> float:
        """Time from full charge to the reserve at a constant total load ``power_w``."""
        if not (math.isfinite(power_w) and power_w > 0):
            raise UserError(f"endurance needs a power > 0 W, got {power_w}")
        return self.usable_wh * J_PER_WH / power_w

    @classmethod
    def from_fdm(cls, fdm: object, aircraft: str = "aircraft") -> BatterySpec:
        """The battery data a loaded JSBSim executive declares (its ``electric/*`` properties);
        an aircraft without them is a :class:`UserError` naming what is missing."""
        names = (
            CAPACITY_WH,
            RESERVE_SOC,
            MOTOR_EFFICIENCY,
            AVIONICS_POWER_W,
            PAYLOAD_POWER_W,
            VOLTAGE_V,
        )
        pm = fdm.get_property_manager()
        missing = [n for n in names[:3] if not pm.hasNode(n)]
        if missing:
            raise UserError(
                f"aircraft '{aircraft}' declares no battery data ({', '.join(missing)}); "
                f"add a Systems/{aircraft}_battery.xml as aircraft/uav_fw has"
            )
        values = [fdm[n] if pm.hasNode(n) else 0.0 for n in names]
        return cls(*values)


class Battery:
    """State of charge of a battery of ``capacity_wh`` that keeps ``reserve_soc`` (0..1) for
    the way home, starting at ``soc`` (full by default).

    :meth:`draw` integrates the load with the trapezoid rule between successive calls, so a
    power sampled at the episode's sample rate gives the energy of the sampled curve.
    """

    def __init__(self, capacity_wh: float, reserve_soc: float = 0.2, soc: float = 1.0) -> None:
        _check_capacity(capacity_wh)
        _check_reserve(reserve_soc)
        if not (math.isfinite(soc) and 0 <= soc <= 1):
            raise UserError(f"battery initial soc must be in [0, 1], got {soc}")
        self.capacity_wh = float(capacity_wh)
        self.reserve_soc = float(reserve_soc)
        self._initial_wh = float(soc) * self.capacity_wh
        self.energy_wh = 0.0  # drawn since the start
        self._last_power_w: float | None = None

    @classmethod
    def from_spec(cls, spec: BatterySpec, soc: float = 1.0) -> Battery:
        return cls(spec.capacity_wh, spec.reserve_soc, soc)

    def draw(self, power_w: float, dt: float) -> None:
        """The load is ``power_w`` now, ``dt`` seconds after the previous call: add the energy
        of that interval (trapezoid between the two powers; the first call, with no previous
        power, takes ``power_w`` as constant). Call ``draw(p0, 0.0)`` to give the first
        sample without drawing anything."""
        if not math.isfinite(power_w):
            raise UserError(f"battery draw: power_w must be finite, got {power_w}")
        if not (math.isfinite(dt) and dt >= 0):
            raise UserError(f"battery draw: dt must be a finite number >= 0, got {dt}")
        prev = power_w if self._last_power_w is None else self._last_power_w
        self.energy_wh += 0.5 * (prev + power_w) * dt / J_PER_WH
        self._last_power_w = float(power_w)

    @property
    def remaining_wh(self) -> float:
        return max(self._initial_wh - self.energy_wh, 0.0)

    @property
    def soc(self) -> float:
        """State of charge, 0..1 (0 when empty; it does not go below)."""
        return self.remaining_wh / self.capacity_wh

    @property
    def at_reserve(self) -> bool:
        """True once the state of charge has fallen to the reserve."""
        return self.soc <= self.reserve_soc

    @property
    def empty(self) -> bool:
        return self.remaining_wh <= 0.0

    def time_to_reserve_s(self, power_w: float) -> float:
        """Seconds until the reserve at a constant ``power_w`` (0 if already there)."""
        if not (math.isfinite(power_w) and power_w > 0):
            raise UserError(f"time_to_reserve_s needs a power > 0 W, got {power_w}")
        left_wh = self.remaining_wh - self.reserve_soc * self.capacity_wh
        return max(left_wh, 0.0) * J_PER_WH / power_w


def _check_capacity(capacity_wh: float) -> None:
    if not (math.isfinite(capacity_wh) and capacity_wh > 0):
        raise UserError(f"battery capacity_wh must be a finite number > 0, got {capacity_wh}")


def _check_reserve(reserve_soc: float) -> None:
    if not (math.isfinite(reserve_soc) and 0 <= reserve_soc < 1):
        raise UserError(f"battery reserve_soc must be in [0, 1), got {reserve_soc}")
