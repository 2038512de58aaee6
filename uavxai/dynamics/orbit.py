"""Loiter orbit guidance: a vector-field law that flies a circle over the ground.

The law is the outer loop of a loiter mode. Whoever flies the aircraft evaluates
:meth:`OrbitGuidance.bank_command` at a fixed rate (10 Hz is plenty: the bank loop inside the
JSBSim autopilot has a 0.4 s time constant) and writes the result as the bank command
(``Aircraft.command(bank_cmd_rad=...)`` or ``JSBSimWorld.command_ownship``).

The field (Beard & McLain, *Small Unmanned Aircraft*, 2012, sec. 10.3): at distance d from
the centre, bearing beta (clockwise from north, as headings are), the desired ground course is

    chi_d = beta + lam * (pi/2 + atan(k (d - R) / R)),   lam = +1 clockwise, -1 otherwise,

i.e. the circle's tangent, turned towards the circle by up to 90 degrees when off it: far
away the aircraft heads for the centre, on the circle it flies the tangent. The bank command
turns the ground course at the rate the field itself turns along the path (feed-forward,
exactly V_g^2 / R on the circle, i.e. the coordinated turn atan(V_g^2 / (g R))) plus a
proportional correction of the course error:

    chi_dot_cmd = dchi_d/dt + (chi_d - chi) / tau,   phi = atan(V_g chi_dot_cmd / g).

Everything is over the ground (ground velocity and ground course), so the circle is a circle
over the ground in wind too; the bank then varies around the orbit with the ground speed.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import TYPE_CHECKING

import numpy as np

from uavxai.errors import UserError
from uavxai.geometry import bank_of_turn_rate, turn_rate_of_bank, wrap_angle
from uavxai.units import G

if TYPE_CHECKING:
    from uavxai.scenario import Scenario

# Fraction of the bank limit the steady orbit may use, so that the correction loop keeps
# roll authority (and the wind's varying ground speed is absorbed) without hitting the limit.
RADIUS_MARGIN = 0.7

# Gains, tuned on the uav_fw in JSBSim (tests/test_dynamics_orbit.py, 12-30 m/s): the course
# loop's time constant is five times the bank hold's 0.4 s, and a distance error decays over
# about R / (k V_g) (2.7 s at 20 m/s on the 106 m orbit), so that the loops do not fight.
# k = 2 captures sooner and tracks wind and gusts tighter than k = 1 or 1.5, with no overshoot.
COURSE_TIME_CONSTANT_S = 2.0
CONVERGENCE_GAIN = 2.0

# Below this ground speed the ground course is undefined (hovering into a head wind).
_MIN_GROUND_SPEED_MPS = 1.0


def radius_for(
    airspeed_mps: float,
    bank_limit_rad: float,
    margin: float = RADIUS_MARGIN,
    wind_mps: float = 0.0,
) -> float:
    """The smallest orbit radius the aircraft flies with ``margin`` of its bank limit to spare:
    R = V^2 / (g tan(margin * phi_max)), with V the largest ground speed on the orbit,
    ``airspeed_mps + wind_mps`` (downwind the same circle needs the most bank)."""
    for name, value in (("airspeed_mps", airspeed_mps), ("wind_mps", wind_mps)):
        if not math.isfinite(value) or value < 0:
            raise UserError(f"orbit {name} must be a finite number >= 0, got {value}")
    if not (math.isfinite(bank_limit_rad) and 0 < bank_limit_rad < math.pi / 2):
        raise UserError(
            f"orbit bank_limit_rad must be in (0, pi/2) (0-90 deg), got {bank_limit_rad}"
        )
    if not (math.isfinite(margin) and 0 < margin <= 1):
        raise UserError(f"orbit margin must be in (0, 1], got {margin}")
    if airspeed_mps <= 0:
        raise UserError(f"orbit airspeed_mps must be > 0, got {airspeed_mps}")
    v = airspeed_mps + wind_mps
    return v * v / (G * math.tan(margin * bank_limit_rad))


def scenario_orbit_radius(scenario: Scenario) -> float:
    """The loiter radius a scenario's mission flies about its service point (the one place
    it is decided: the mission flies it, orbit-aware service placement scores it):
    ``mission.orbit_radius_m`` if given, else :func:`radius_for` the ownship's start airspeed,
    ``avoidance.bank_limit_deg`` and the scenario's steady wind."""
    from uavxai.dynamics.environment import EnvironmentConfig  # imports jsbsim

    given = scenario.mission.orbit_radius_m
    if given:
        return float(given)
    start, av = scenario.ownship.start, scenario.avoidance
    wind = EnvironmentConfig.from_scenario(scenario).wind_speed_mps
    return radius_for(start.speed_mps, math.radians(av.bank_limit_deg), wind_mps=wind)


class OrbitGuidance:
    """Fly a circle of ``radius_m`` about ``centre_xy`` (local ENU metres), clockwise seen from
    above unless ``clockwise`` is False, banking at most ``bank_limit_rad``."""

    def __init__(
        self,
        centre_xy: Sequence[float],
        radius_m: float,
        clockwise: bool = True,
        bank_limit_rad: float = math.radians(30.0),
        course_time_constant_s: float = COURSE_TIME_CONSTANT_S,
        convergence_gain: float = CONVERGENCE_GAIN,
    ) -> None:
        cx, cy = (float(c) for c in centre_xy)
        if not (math.isfinite(cx) and math.isfinite(cy)):
            raise UserError(f"orbit centre must be finite (x, y) metres, got {centre_xy!r}")
        if not (math.isfinite(radius_m) and radius_m > 0):
            raise UserError(f"orbit radius_m must be a finite number > 0, got {radius_m}")
        if not (math.isfinite(bank_limit_rad) and 0 < bank_limit_rad < math.pi / 2):
            raise UserError(
                f"orbit bank_limit_rad must be in (0, pi/2) (0-90 deg), got {bank_limit_rad}"
            )
        if not (course_time_constant_s > 0 and convergence_gain > 0):
            raise UserError("orbit course_time_constant_s and convergence_gain must be > 0")
        self.centre = (cx, cy)
        self.radius_m = float(radius_m)
        self.clockwise = bool(clockwise)
        self.bank_limit_rad = float(bank_limit_rad)
        self.tau = float(course_time_constant_s)
        self.k = float(convergence_gain)
        self._lam = 1.0 if self.clockwise else -1.0

    def __repr__(self) -> str:
        return (
            f"OrbitGuidance(centre=({self.centre[0]:.1f}, {self.centre[1]:.1f}), "
            f"radius_m={self.radius_m:.1f}, clockwise={self.clockwise})"
        )

    def distance_error(self, pos_xy: Sequence[float]) -> float:
        """Distance from the circle, m: positive outside, negative inside."""
        return math.hypot(pos_xy[0] - self.centre[0], pos_xy[1] - self.centre[1]) - self.radius_m

    def desired_course(self, pos_xy: Sequence[float]) -> float:
        """The field's ground course at ``pos_xy``, rad clockwise from north."""
        dx, dy = pos_xy[0] - self.centre[0], pos_xy[1] - self.centre[1]
        d = math.hypot(dx, dy)
        beta = math.atan2(dx, dy)  # bearing of the aircraft from the centre
        e = self.k * (d - self.radius_m) / self.radius_m
        return beta + self._lam * (math.pi / 2 + math.atan(e))

    def bank_command(
        self, pos_xy: Sequence[float], vel_xy: Sequence[float], airspeed: float
    ) -> float:
        """Bank command, rad (right wing down positive), within the bank limit, for the
        aircraft at ``pos_xy`` with ground velocity ``vel_xy`` (east, north m/s) and true
        airspeed ``airspeed`` (used only when the ground speed is too small to give a
        course)."""
        x, y = float(pos_xy[0]), float(pos_xy[1])
        vx, vy = float(vel_xy[0]), float(vel_xy[1])
        if not all(math.isfinite(v) for v in (x, y, vx, vy)):
            return 0.0  # a diverged state (the world reports it): never pass NaN on
        dx, dy = x - self.centre[0], y - self.centre[1]
        d = max(math.hypot(dx, dy), 1e-6)
        vg = math.hypot(vx, vy)
        lim = self.bank_limit_rad
        if vg < _MIN_GROUND_SPEED_MPS:
            # No course to correct: hold the turn the circle needs at this airspeed.
            va = airspeed if math.isfinite(airspeed) else 0.0
            return self._lam * min(math.atan(va * va / (G * self.radius_m)), lim)
        r = self.radius_m
        beta = math.atan2(dx, dy)
        chi = math.atan2(vx, vy)  # ground course
        e = self.k * (d - r) / r
        chi_d = beta + self._lam * (math.pi / 2 + math.atan(e))
        # Rate at which the field's course changes along the path actually flown.
        d_dot = vg * math.cos(chi - beta)
        beta_dot = vg * math.sin(chi - beta) / d
        chi_d_dot = beta_dot + self._lam * (self.k / r) / (1.0 + e * e) * d_dot
        turn_rate = chi_d_dot + wrap_angle(chi_d - chi) / self.tau
        bank = bank_of_turn_rate(turn_rate, vg)
        return min(max(bank, -lim), lim)

    def fly(
        self,
        pos_xy: Sequence[float],
        vel_xy: Sequence[float],
        bank_rad: float,
        roll_rate_rad_s: float,
        duration_s: float,
        step_s: float,
    ) -> np.ndarray:
        """Where the law takes an aircraft now at ``pos_xy`` with ground velocity ``vel_xy``
        and bank ``bank_rad``: (n + 1, 2) positions every ``step_s`` (the outer loop's period)
        over ``duration_s``, from now. Kinematic: the bank follows each command at the roll
        rate limit, the ground course turns at the coordinated rate of that bank at the ground
        speed, which stays as it is. It is the orbit law's own way onto the circle (from far
        out heading away it turns a circle of its own first; issue 32, fleet-mission.yaml
        seed 1), which the circle itself does not say."""
        x, y = float(pos_xy[0]), float(pos_xy[1])
        vx, vy = float(vel_xy[0]), float(vel_xy[1])
        speed = max(math.hypot(vx, vy), _MIN_GROUND_SPEED_MPS)
        course, phi = math.atan2(vx, vy), float(bank_rad)
        n = max(int(round(duration_s / step_s)), 0)
        out = np.empty((n + 1, 2))
        out[0] = x, y
        roll = roll_rate_rad_s * step_s
        for k in range(1, n + 1):
            cmd = self.bank_command((x, y), (vx, vy), speed)
            phi += min(max(cmd - phi, -roll), roll)
            course += turn_rate_of_bank(phi, speed) * step_s
            vx, vy = speed * math.sin(course), speed * math.cos(course)
            x, y = x + vx * step_s, y + vy * step_s
            out[k] = x, y
        return out
