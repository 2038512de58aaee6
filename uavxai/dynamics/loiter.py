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


def orbit_guidance(
    bank_limit_deg: float, x: float, y: float, radius_m: float, clockwise: bool
):
    """The loiter law for an orbit of ``radius_m`` about (x, y) within the bank limit
    (`avoidance.bank_limit_deg`): the one the worlds fly and the one the mission predicts
    (``uavxai.sim.mission.way_clearance``), built here only."""
    from uavxai.dynamics.orbit import OrbitGuidance

    return OrbitGuidance(
        (float(x), float(y)),
        float(radius_m),
        clockwise=clockwise,
        bank_limit_rad=math.radians(bank_limit_deg),
    )


class LoiterAutopilot:
    """The loiter mode of a world's ownship (mixed into both worlds, which provide
    ``scenario``, ``state()`` and ``_bank_from_guidance``)."""

    _orbit = None
    # a fleet's members' loiter laws, row -> OrbitGuidance (a world without members: none)
    _member_orbits: dict = {}

    def command_orbit(self, x: float, y: float, radius_m: float, clockwise: bool = True) -> None:
        """Orbit (x, y) at ``radius_m`` at the height target, until a bank command takes
        over."""
        self._orbit = orbit_guidance(self._bank_limit_deg, x, y, radius_m, clockwise)
        self._fly_orbit()

    def command_member_orbit(
        self, row: int, x: float, y: float, radius_m: float, clockwise: bool = True
    ) -> None:
        """Fleet member ``row``'s :meth:`command_orbit`."""
        self._member_orbits = {**self._member_orbits, row: orbit_guidance(
            self._bank_limit_deg, x, y, radius_m, clockwise)}  # fmt: skip
        self._fly_member_orbits()

    def _fly_member_orbits(self) -> None:
        s = self.state()
        for row, orbit in self._member_orbits.items():
            bank = orbit.bank_command(s.pos[row, :2], s.vel[row, :2], float(s.airspeed[row]))
            self._bank_from_guidance(bank, row)

    @property
    def _bank_limit_deg(self) -> float:
        return self.scenario.avoidance.bank_limit_deg

    @property
    def orbit(self):
        """The active loiter orbit (an OrbitGuidance), or None when the bank is commanded."""
        return self._orbit

    def _fly_orbit(self) -> None:
        s = self.state()
        bank = self._orbit.bank_command(s.pos[0, :2], s.vel[0, :2], float(s.airspeed[0]))
        self._bank_from_guidance(bank)

    def _bank_from_guidance(self, bank_rad: float, row: int = 0) -> None:
        raise NotImplementedError


class ScheduledWorld(LoiterAutopilot):
    """What both worlds share: a clock in integrator ticks, the intruders' pilots every
    ``PILOT_PERIOD_S``, persistent traffic (``intruders.flow``) at the same instants, and the
    ownship's loiter law every ``GUIDANCE_PERIOD_S``. A world provides ``_integrate(ticks)``,
    ``_halted()``, ``_command_intruder(row, bank, speed, alt)`` (``alt`` None: hold the height)
    and ``_replace(entries)``."""

    member_rows: range = range(0)  # a fleet's members' rows (JSBSimWorld; none here)

    @property
    def fleet_rows(self) -> list[int]:
        """The rows of the fleet's aircraft: the ownship and the members."""
        return [0, *self.member_rows]

    def _init_schedule(self, scenario: Scenario, seed: int, n_intruders: int) -> None:
        from uavxai.dynamics.behaviours import PILOT_PERIOD_S
        from uavxai.dynamics.flow import TrafficFlow, entry_clearance

        self._steps = 0
        self._pilot_period = max(1, round(PILOT_PERIOD_S / self.dt))
        self._guidance_period = max(1, round(GUIDANCE_PERIOD_S / self.dt))
        # newcomers are numbered after everyone drawn: a track, trail or row is one aircraft
        self._flow = TrafficFlow.from_scenario(scenario, seed=seed, first_number=n_intruders + 1)
        self._clearance = entry_clearance(scenario.world.x, scenario.world.y)

    @property
    def t(self) -> float:
        return self._steps * self.dt

    def lookahead(self, ticks: int, every: int) -> int:
        """Fly the intruders ahead of the ownship while its next command is decided
        elsewhere; the ticks flown ahead. Here none: a world that flies a period in closed
        form (the kinematic one) has nothing to gain (JSBSimWorld overrides it)."""
        return 0

    def advance(self, seconds: float) -> None:
        self.step(round(seconds / self.dt))

    def step(self, n: int = 1) -> None:
        """Advance by ``n`` ticks, the pilots and the loiter law on their periods.

        Each chunk between two of those instants is integrated in one piece: the kinematic
        world flies it in closed form (a longer step costs no more), JSBSim tick by tick."""
        left = int(n)
        while left > 0 and not self._halted():
            chunk = min(left, self._pilot_period - self._steps % self._pilot_period)
            guided = self._orbit is not None or self._member_orbits
            if guided:  # the loiter law's period cuts only while it flies
                chunk = min(chunk, self._guidance_period - self._steps % self._guidance_period)
            if not self._integrate(chunk):
                return
            self._steps += chunk
            left -= chunk
            self._cached = None
            if self._steps % self._pilot_period == 0:
                self._fly_pilots()
            if guided and self._steps % self._guidance_period == 0:
                if self._orbit is not None:
                    self._fly_orbit()
                if self._member_orbits:
                    self._fly_member_orbits()

    @staticmethod
    def _finite_commands(**given: float | None) -> None:
        """A UserError for a non-finite autopilot input (None: left as it is)."""
        from uavxai.errors import UserError

        for key, value in given.items():
            if value is not None and not math.isfinite(value):
                raise UserError(f"command_ownship: {key} must be a finite number, got {value}")

    def _fly_pilots(self) -> None:
        """Every pilot second: leavers replaced by newcomers, then each pilot's commands."""
        s = self.state()
        if self._stopped(s) or s.n < 2:
            return
        s = self.state()  # the check may have replaced a lost intruder
        if self._flow is not None:
            entries = self._flow.replace(
                s.pos[1 : 1 + len(self._pilots)],  # the intruders' rows: a fleet's come after
                keep_clear=s.pos[self.fleet_rows],
                min_distance_m=self._clearance,
            )
            if entries:
                self._replace(entries)
                s = self.state()
        for i, pilot in enumerate(self._pilots, start=1):
            bank, speed = pilot.command(s.t, s.pos[i], s.vel[i], float(s.att[i, 2]))
            self._command_intruder(i, bank, speed, pilot.alt_target(s.t))
