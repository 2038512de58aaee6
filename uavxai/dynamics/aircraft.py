"""One JSBSim aircraft flown through its autopilot: a trimmed airborne start, commands, state.

The autopilot is part of the aircraft (``aircraft/<name>/Systems/*_autopilot.xml``); Python
only writes its ``ap/*`` inputs. Property names and limits are documented in
``aircraft/uav_fw/README.md``.
"""

from __future__ import annotations

import logging
import math

import jsbsim

from uavxai.dynamics.energy import SHAFT_POWER_HP, THROTTLE, WATTS_PER_HP, BatterySpec
from uavxai.dynamics.fdm import load_fdm
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.errors import UserError
from uavxai.units import FT, KT

log = logging.getLogger(__name__)

# Autopilot inputs (SI)
ENGAGED = "ap/engaged"
BANK_CMD = "ap/bank-cmd-rad"
ACCEL_CMD = "ap/accel-cmd-mps2"
SPEED_TARGET = "ap/speed-target-mps"
ALT_TARGET = "ap/alt-target-m"  # height above ground: the local frame's h
BANK_LIMIT = "ap/bank-limit-rad"
CLIMB_RATE_LIMIT = "ap/climb-rate-limit-mps"
SPEED_MIN = "ap/speed-min-mps"
SPEED_MAX = "ap/speed-max-mps"

# Weather (JSBSim 1.3 FGWinds; names checked by reading them back, tests/test_environment.py)
WIND_NORTH = "atmosphere/wind-north-fps"  # velocity of the air mass, NED, ft/s
WIND_EAST = "atmosphere/wind-east-fps"
WIND_DOWN = "atmosphere/wind-down-fps"
TURB_TYPE = "atmosphere/turb-type"  # 0 none, 3 Milspec (Dryden spectrum, MIL-F-8785C)
TURB_SEVERITY = "atmosphere/turbulence/milspec/severity"  # probability-of-exceedance row
TURB_W20 = "atmosphere/turbulence/milspec/windspeed_at_20ft_AGL-fps"
TURB_SEED = "atmosphere/randomseed"
TURB_MILSPEC = 3

# MIL-F-8785C: below 1000 ft the intensity scales with the wind speed at 20 ft (light 15 kt,
# moderate 30 kt, severe 45 kt); above 2000 ft it follows the probability of exceedance
# 1e-2, 1e-3 and 1e-5, which are rows 3, 4 and 6 of JSBSim's severity table.
# JSBSim evaluates these altitude bands at the height above SEA LEVEL, not above ground: over
# the default origin (400 m) an aircraft at 120 m is at 1700 ft, in the 1000-2000 ft blend of
# the two models, and its gusts are about 1.25 times the low-altitude intensities (measured:
# moderate sigma_u 2.5 m/s instead of 2.0; tests/test_dynamics_environment.py checks the
# low-altitude values over a sea-level origin). JSBSim 1.3 keeps the filter states per
# executive, so aircraft stepped in lockstep in one process do not disturb each other.
TURBULENCE: dict[str, tuple[int, float]] = {
    "none": (0, 0.0),
    "light": (3, 15.0),
    "moderate": (4, 30.0),
    "severe": (6, 45.0),
}

COMMANDS = {
    "bank_cmd_rad": BANK_CMD,
    "accel_cmd_mps2": ACCEL_CMD,
    "speed_target_mps": SPEED_TARGET,
    "alt_target_m": ALT_TARGET,
}

# What state() needs, in this order (see raw_state).
STATE_PROPERTIES = (
    "position/lat-geod-deg",
    "position/long-gc-deg",
    "position/h-agl-ft",
    "velocities/v-east-fps",
    "velocities/v-north-fps",
    "velocities/v-down-fps",
    "attitude/phi-rad",
    "attitude/theta-rad",
    "attitude/psi-rad",
    "velocities/vt-fps",
)

# JSBSim's trim marches the propeller speed with 0.5 s steps from its current value; from
# standstill the first step overshoots wildly, so the propeller is spun up first.
_SPIN_UP_S = 0.5
_SPIN_UP_THROTTLE = 0.3
_TRIM_FULL = 1


class Aircraft:
    """A JSBSim executive with a trimmed airborne start and its autopilot engaged.

    ``run`` is the bare ``FGFDMExec.run`` (the world calls it in its inner loop).
    """

    def __init__(self, name: str, frame: LocalFrame, dt: float, seed: int) -> None:
        self.name = name
        self.frame = frame
        self.dt = dt
        self._battery_spec: BatterySpec | None = None  # read from the package when asked
        self.fdm = load_fdm(name, dt)
        self.fdm["simulation/randomseed"] = seed
        self.run = self.fdm.run
        pm = self.fdm.get_property_manager()
        self._get = [pm.get_node(p).get_double_value for p in STATE_PROPERTIES]
        self._set = {k: pm.get_node(p).set_double_value for k, p in COMMANDS.items()}
        self._set["speed_max_mps"] = pm.get_node(SPEED_MAX).set_double_value
        self.trimmed = False
        self._wind_ne = (0.0, 0.0)

    @property
    def speed_range(self) -> tuple[float, float]:
        """The airspeeds the aircraft's autopilot accepts (its own defaults until changed)."""
        return self.fdm[SPEED_MIN], self.fdm[SPEED_MAX]

    def start(self, x: float, y: float, h: float, heading_rad: float, speed_mps: float) -> bool:
        """Place the aircraft in level flight at local (x, y, h), trim it, engage the autopilot
        to hold that heading (wings level), height and speed. Returns whether the trim
        converged; if not, the autopilot flies it from the untrimmed state."""
        f = self.fdm
        lat, lon, _ = self.frame.to_geodetic(x, y, h)
        f["ic/terrain-elevation-ft"] = self.frame.alt0 / FT
        f["ic/lat-geod-deg"] = float(lat)
        f["ic/long-gc-deg"] = float(lon)
        f["ic/h-agl-ft"] = h / FT
        f["ic/psi-true-rad"] = heading_rad
        wind_n, wind_e = self._wind_ne
        if wind_n == 0.0 and wind_e == 0.0:
            f["ic/vt-fps"] = speed_mps / FT
            f["ic/gamma-rad"] = 0.0
        else:
            # In wind, JSBSim's ic/vt-fps keeps the direction of the air-relative velocity
            # it had (backwards from a standstill), so the ground velocity of the wind
            # triangle is given instead: air velocity along the heading, plus the wind.
            f["ic/vn-fps"] = (speed_mps * math.cos(heading_rad) + wind_n) / FT
            f["ic/ve-fps"] = (speed_mps * math.sin(heading_rad) + wind_e) / FT
            f["ic/vd-fps"] = 0.0
        f[ENGAGED] = 0.0
        # The trim is of the steady state, in the steady wind: with the turbulence on it
        # chases the gusts and mostly fails (most aircraft of a moderate-turbulence run started
        # untrimmed), and a failed trim can leave the propeller, and with it the whole state,
        # NaN. The gusts start once the aircraft is trimmed.
        turbulence = f[TURB_TYPE]
        f[TURB_TYPE] = 0
        f.run_ic()
        # Every engine running (a piston engine starts stopped; the electric one is unchanged)
        f["propulsion/set-running"] = -1
        f["fcs/throttle-cmd-norm"] = _SPIN_UP_THROTTLE
        for _ in range(round(_SPIN_UP_S / self.dt)):
            f.run()
        try:
            f.do_trim(_TRIM_FULL)  # restarts from the initial conditions
            self.trimmed = True
        except jsbsim.TrimFailureError:
            self.trimmed = False
            log.warning(
                "%s: no trim at %.1f m/s, %.0f m; the autopilot starts from the untrimmed state",
                self.name,
                speed_mps,
                h,
            )
        f[TURB_TYPE] = turbulence
        f.set_sim_time(0.0)
        self.command(
            bank_cmd_rad=0.0, accel_cmd_mps2=0.0, speed_target_mps=speed_mps, alt_target_m=h
        )
        f[ENGAGED] = 1.0
        return self.trimmed

    def set_environment(
        self,
        wind_ne_mps: tuple[float, float] = (0.0, 0.0),
        turbulence: str = "none",
        seed: int = 0,
    ) -> None:
        """Steady wind and Milspec (Dryden) turbulence around this aircraft.

        ``wind_ne_mps`` is the velocity of the air mass over the ground, (north, east) m/s
        (see :func:`wind_ne_from`); ``turbulence`` one of :data:`TURBULENCE`, the
        MIL-F-8785C severities; ``seed`` seeds JSBSim's turbulence noise, so a run repeats.
        Call it before :meth:`start` so that the trim is found in the wind (the trim keeps
        the true airspeed and heading asked for, the ground speed follows); later calls
        change the weather mid-flight.
        """
        if turbulence not in TURBULENCE:
            raise UserError(
                f"environment.turbulence = {turbulence!r}; allowed: {', '.join(TURBULENCE)}"
            )
        north, east = (float(w) for w in wind_ne_mps)
        if not (math.isfinite(north) and math.isfinite(east)):
            raise UserError(f"environment.wind must be finite, got {wind_ne_mps!r}")
        f = self.fdm
        self._wind_ne = (north, east)
        # run_ic (and the trim, which restarts from the initial conditions) copies the
        # initial-condition wind into the atmosphere, so both are set. ic/vw-dir-deg is the
        # direction the air moves TO (read back: 90 gives a wind towards the east).
        f["ic/vw-mag-fps"] = math.hypot(north, east) / FT
        f["ic/vw-dir-deg"] = math.degrees(math.atan2(east, north)) % 360.0
        f[WIND_NORTH] = north / FT
        f[WIND_EAST] = east / FT
        f[WIND_DOWN] = 0.0
        severity, w20_kt = TURBULENCE[turbulence]
        # The Milspec model draws its white noise from the generator seeded here.
        f[TURB_SEED] = int(seed) & 0x7FFFFFFF
        f[TURB_TYPE] = TURB_MILSPEC if severity else 0
        f[TURB_SEVERITY] = severity
        f[TURB_W20] = w20_kt * KT / FT

    def wind_ne_mps(self) -> tuple[float, float]:
        """The steady wind as JSBSim has it, (north, east) m/s (turbulence not included)."""
        return self.fdm[WIND_NORTH] * FT, self.fdm[WIND_EAST] * FT

    def set_limits(
        self,
        bank_limit_rad: float | None = None,
        speed_range: tuple[float, float] | None = None,
    ) -> None:
        if bank_limit_rad is not None:
            self.fdm[BANK_LIMIT] = bank_limit_rad
        if speed_range is not None:
            self.fdm[SPEED_MIN], self.fdm[SPEED_MAX] = speed_range

    def command(
        self,
        bank_cmd_rad: float | None = None,
        accel_cmd_mps2: float | None = None,
        speed_target_mps: float | None = None,
        alt_target_m: float | None = None,
        speed_max_mps: float | None = None,
    ) -> None:
        """Write autopilot inputs; None leaves one unchanged. ``speed_max_mps`` is the
        autopilot's airspeed ceiling (its speed target never passes it)."""
        for key, value in (
            ("bank_cmd_rad", bank_cmd_rad),
            ("accel_cmd_mps2", accel_cmd_mps2),
            ("speed_target_mps", speed_target_mps),
            ("alt_target_m", alt_target_m),
            ("speed_max_mps", speed_max_mps),
        ):
            if value is not None:
                self._set[key](float(value))

    def read_command(self) -> dict[str, float]:
        return {key: self.fdm[prop] for key, prop in COMMANDS.items()}

    def raw_state(self) -> list[float]:
        """STATE_PROPERTIES in JSBSim units (degrees of lat/lon, feet, radians)."""
        return [get() for get in self._get]

    # ---------------------------------------------- electrical (see uavxai.dynamics.energy)
    def battery_spec(self) -> BatterySpec:
        """The battery and electrical loads the aircraft package declares."""
        if self._battery_spec is None:
            self._battery_spec = BatterySpec.from_fdm(self.fdm, self.name)
        return self._battery_spec

    def shaft_power_w(self) -> float:
        """The motor's shaft power now, W, as JSBSim's electric engine computes it."""
        return self.fdm[SHAFT_POWER_HP] * WATTS_PER_HP

    def motor_power_w(self) -> float:
        """The electrical power the motor and its ESC take from the battery now, W: the
        shaft power over the package's motor efficiency."""
        return self.shaft_power_w() / self.battery_spec().motor_efficiency

    def electric_power_w(self) -> float:
        """The battery's whole load now, W: the motor plus the avionics and payload."""
        return self.motor_power_w() + self.battery_spec().constant_load_w

    def throttle(self) -> float:
        """The motor's throttle, 0..1 (autopilot plus trim, after the mixer's clip)."""
        return self.fdm[THROTTLE]

    def close(self) -> None:
        self.run = None
        self._get = []
        self._set = {}
        self.fdm = None


def heading_from_deg(heading_deg: float) -> float:
    """Scenario heading (degrees, any sign) to radians in [0, 2 pi)."""
    return math.radians(heading_deg % 360.0)


def wind_ne_from(speed_mps: float, from_deg: float) -> tuple[float, float]:
    """(north, east) velocity of the air mass for a wind of ``speed_mps`` blowing FROM
    ``from_deg`` (clockwise from north, as in weather reports: 270 is a west wind, blowing
    towards the east)."""
    if not (math.isfinite(speed_mps) and speed_mps >= 0):
        raise UserError(f"environment.wind.speed_mps must be >= 0, got {speed_mps}")
    if not math.isfinite(from_deg):
        raise UserError(f"environment.wind.from_deg must be a finite number, got {from_deg}")
    towards = math.radians(from_deg) + math.pi
    return speed_mps * math.cos(towards), speed_mps * math.sin(towards)
