"""One JSBSim aircraft flown through its autopilot: a trimmed airborne start, commands, state.

The autopilot is part of the aircraft (``aircraft/<name>/Systems/*_autopilot.xml``); Python
only writes its ``ap/*`` inputs. Property names and limits are documented in
``aircraft/uav_fw/README.md``.
"""

from __future__ import annotations

import logging
import math

import jsbsim

from uavxai.dynamics.fdm import load_fdm
from uavxai.dynamics.geodesy import LocalFrame

log = logging.getLogger(__name__)

FT = 0.3048  # JSBSim speaks feet

# Autopilot inputs (SI)
ENGAGED = "ap/engaged"
BANK_CMD = "ap/bank-cmd-rad"
ACCEL_CMD = "ap/accel-cmd-mps2"
SPEED_TARGET = "ap/speed-target-mps"
ALT_TARGET = "ap/alt-target-m"  # height above ground: the local frame's h
BANK_LIMIT = "ap/bank-limit-rad"
ROLL_RATE_LIMIT = "ap/roll-rate-limit-rad_sec"
CLIMB_RATE_LIMIT = "ap/climb-rate-limit-mps"
SPEED_MIN = "ap/speed-min-mps"
SPEED_MAX = "ap/speed-max-mps"

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
        self.fdm = load_fdm(name, dt)
        self.fdm["simulation/randomseed"] = seed
        self.run = self.fdm.run
        pm = self.fdm.get_property_manager()
        self._get = [pm.get_node(p).get_double_value for p in STATE_PROPERTIES]
        self._set = {k: pm.get_node(p).set_double_value for k, p in COMMANDS.items()}
        self.trimmed = False

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
        f["ic/vt-fps"] = speed_mps / FT
        f["ic/gamma-rad"] = 0.0
        f[ENGAGED] = 0.0
        f.run_ic()
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
        f.set_sim_time(0.0)
        self.command(
            bank_cmd_rad=0.0, accel_cmd_mps2=0.0, speed_target_mps=speed_mps, alt_target_m=h
        )
        f[ENGAGED] = 1.0
        return self.trimmed

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
    ) -> None:
        """Write autopilot inputs; None leaves one unchanged."""
        for key, value in (
            ("bank_cmd_rad", bank_cmd_rad),
            ("accel_cmd_mps2", accel_cmd_mps2),
            ("speed_target_mps", speed_target_mps),
            ("alt_target_m", alt_target_m),
        ):
            if value is not None:
                self._set[key](float(value))

    def read_command(self) -> dict[str, float]:
        return {key: self.fdm[prop] for key, prop in COMMANDS.items()}

    def raw_state(self) -> list[float]:
        """STATE_PROPERTIES in JSBSim units (degrees of lat/lon, feet, radians)."""
        return [get() for get in self._get]

    def close(self) -> None:
        self.run = None
        self._get = []
        self._set = {}
        self.fdm = None


def heading_from_deg(heading_deg: float) -> float:
    """Scenario heading (degrees, any sign) to radians in [0, 2 pi)."""
    return math.radians(heading_deg % 360.0)
