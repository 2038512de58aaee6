"""The weather of a scenario (`environment:`): a steady wind and a turbulence severity, as
plain data that both dynamics use.

The JSBSim world hands it to every aircraft (:meth:`Aircraft.set_environment`, before
``start``); a kinematic model adds :attr:`EnvironmentConfig.wind_enu` to the air velocity it
flies (turbulence is JSBSim-only: the kinematic model has no gust response to feed it to).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from uavxai.dynamics.aircraft import TURBULENCE, wind_ne_from
from uavxai.errors import UserError
from uavxai.geometry import wrap_angle
from uavxai.scenario import Environment, Scenario
from uavxai.units import FT, KT

_DEFAULT = Environment()  # the schema's defaults (environment:), declared there once

@dataclass(frozen=True)
class EnvironmentConfig:
    wind_speed_mps: float = _DEFAULT.wind.speed_mps
    wind_from_deg: float = _DEFAULT.wind.from_deg  # blows FROM, clockwise from north
    turbulence: str = _DEFAULT.turbulence  # none | light | moderate | severe

    def __post_init__(self) -> None:
        wind_ne_from(self.wind_speed_mps, self.wind_from_deg)  # validates both
        if self.turbulence not in TURBULENCE:
            raise UserError(
                f"environment.turbulence = {self.turbulence!r}; allowed: {', '.join(TURBULENCE)}"
            )

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> EnvironmentConfig:
        """The scenario's ``environment`` section."""
        env = scenario.environment
        return cls(env.wind.speed_mps, env.wind.from_deg, env.turbulence)

    @property
    def wind_ne(self) -> tuple[float, float]:
        """(north, east) velocity of the air mass, m/s (Aircraft.set_environment's input)."""
        return wind_ne_from(self.wind_speed_mps, self.wind_from_deg)

    @property
    def wind_enu(self) -> tuple[float, float, float]:
        """(x east, y north, h up) velocity of the air mass, m/s: add it to an air velocity
        to get the ground velocity."""
        north, east = self.wind_ne
        return east, north, 0.0

    def gust_airspeed_sigma_mps(self, h_m: float = 120.0) -> float:
        """The intensity of the gusts along the flight path, sigma_u (m/s), at ``h_m`` above
        ground: MIL-F-8785C's low-altitude 0.1 W20 / (0.177 + 0.000823 h_ft)^0.4 for this
        severity's wind at 20 ft (moderate: 2.0 m/s at 120 m); 0 in steady air. JSBSim's
        gusts over an elevated origin are somewhat stronger (see aircraft.py)."""
        w20 = TURBULENCE[self.turbulence][1] * KT
        return 0.1 * w20 / (0.177 + 0.000823 * h_m / FT) ** 0.4

    @property
    def calm(self) -> bool:
        return self.wind_speed_mps == 0.0 and self.turbulence == "none"

    def crab_angle_rad(self, heading_rad: float, airspeed_mps: float) -> float:
        """Ground track minus heading of an aircraft holding ``heading_rad`` at
        ``airspeed_mps`` in this wind (the wind triangle), in (-pi, pi]."""
        north, east = self.wind_ne
        track = math.atan2(
            airspeed_mps * math.sin(heading_rad) + east,
            airspeed_mps * math.cos(heading_rad) + north,
        )
        return wrap_angle(track - heading_rad)
