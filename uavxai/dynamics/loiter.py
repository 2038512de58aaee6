"""The ownship autopilot's loiter mode, as the worlds run it.

The guidance law itself (:class:`uavxai.dynamics.orbit.OrbitGuidance`) turns the aircraft's
position and ground velocity into a bank command; the world evaluates it every
``GUIDANCE_PERIOD_S`` of simulated time and writes the command to the inner loops, as an
autopilot's outer loop would. A bank command from outside takes the aircraft off the orbit.
"""

from __future__ import annotations

import math

from uavxai.scenario import Scenario

GUIDANCE_PERIOD_S = 0.1  # the outer loop's rate (10 Hz), a multiple of the integrator's tick


def orbit_guidance(scenario: Scenario, x: float, y: float, radius_m: float, clockwise: bool):
    """The loiter law for an orbit of ``radius_m`` about (x, y) within the scenario's bank
    limit."""
    from uavxai.dynamics.orbit import OrbitGuidance

    return OrbitGuidance(
        (float(x), float(y)),
        float(radius_m),
        clockwise=clockwise,
        bank_limit_rad=math.radians(scenario.avoidance.bank_limit_deg),
    )


class LoiterAutopilot:
    """The loiter mode of a world's ownship (mixed into both worlds, which provide
    ``scenario``, ``state()`` and ``_bank_from_guidance``)."""

    _orbit = None

    def command_orbit(self, x: float, y: float, radius_m: float, clockwise: bool = True) -> None:
        """Orbit (x, y) at ``radius_m`` at the height target, until a bank command takes
        over."""
        self._orbit = orbit_guidance(self.scenario, x, y, radius_m, clockwise)
        self._fly_orbit()

    @property
    def orbit(self):
        """The active loiter orbit (an OrbitGuidance), or None when the bank is commanded."""
        return self._orbit

    def _fly_orbit(self) -> None:
        s = self.state()
        bank = self._orbit.bank_command(s.pos[0, :2], s.vel[0, :2], float(s.airspeed[0]))
        self._bank_from_guidance(bank)

    def _bank_from_guidance(self, bank_rad: float) -> None:
        raise NotImplementedError
