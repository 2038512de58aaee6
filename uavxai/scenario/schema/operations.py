"""What the flight is for and what it meets: `operator` (scripted ground-station commands),
`mission` (time on station, return home), `fleet` (how many ownships fly it) and `encounters`
(statistical pairwise encounters)."""

from __future__ import annotations

from pathlib import Path
from typing import Annotated, Literal

from pydantic import Field, field_validator, model_validator

from uavxai.scenario.schema.base import (
    MAX_HEIGHT_M,
    MAX_M,
    AircraftName,
    Finite,
    Section,
    check_slug,
)

# ------------------------------------------------------------------------------------- operator
OPERATOR_MODES = ("AUTO", "GUIDED", "LOITER", "RTL")


class OrbitAim(Section):
    x: Finite
    y: Finite
    h: Finite
    radius_m: Annotated[float, Field(ge=1, le=MAX_M)] = 150.0
    clockwise: bool = True


class OperatorCommandSpec(Section):
    """One timed command of the scripted operator: at ``t`` (s of simulated time) exactly one
    of a height, an airspeed, a flight mode, a point to go to or an orbit."""

    t: Annotated[float, Field(ge=0, le=86_400, allow_inf_nan=False)]
    altitude_m: Finite | None = None
    speed_mps: Annotated[float, Field(gt=0, le=1000)] | None = None
    mode: Literal["AUTO", "GUIDED", "LOITER", "RTL"] | None = None
    goto: tuple[Finite, Finite, Finite] | None = None
    orbit: OrbitAim | None = None

    @model_validator(mode="after")
    def _one(self) -> OperatorCommandSpec:
        given = [k for k in ("altitude_m", "speed_mps", "mode", "goto", "orbit")
                 if getattr(self, k) is not None]  # fmt: skip
        if len(given) != 1:
            raise ValueError(
                "each operator command gives t and exactly one of altitude_m, speed_mps, "
                f"mode ({', '.join(OPERATOR_MODES)}), goto [x, y, h] or orbit {{x, y, h, "
                f"radius_m}}; this one gives {', '.join(given) or 'none'}"
            )
        return self


class Operator(Section):
    """A scripted operator: timed ground-station commands, sent as MAVLink frames through the
    bridge's own decoder (BlueSky's timed stack commands, for a pilot in the loop)."""

    system_id: Annotated[int, Field(ge=1, le=255)] = 255
    commands: Annotated[list[OperatorCommandSpec], Field(max_length=1000)] = []


# -------------------------------------------------------------------------------------- mission
class Mission(Section):
    service_s: Annotated[float, Field(ge=0, le=86_400)] = 300.0
    return_home: bool = True
    orbit_radius_m: Annotated[float, Field(gt=0, le=10_000)] | None = None  # null: from bank


# ---------------------------------------------------------------------------------------- fleet
MAX_FLEET = 8  # members are JSBSim executives flown and planned for on the simulation's core


class FleetLeave(Section):
    """A member that leaves early, scripted (docs/fleet.md, "A member leaving early"): at
    ``at_s`` (s of simulated time) member ``member`` turns for home as at its battery's
    reserve; the others' placement is re-planned for the whole crowd."""

    member: Annotated[int, Field(ge=0, le=MAX_FLEET - 1)]
    at_s: Annotated[float, Field(gt=0, le=86_400, allow_inf_nan=False)]


class Fleet(Section):
    """How many ownships fly the mission together (docs/fleet.md): member 0 is the ownship at
    ``ownship.start``; member i starts ``i * spacing_m`` to the right of it, abreast."""

    size: Annotated[int, Field(ge=1, le=MAX_FLEET)] = 1
    spacing_m: Annotated[float, Field(ge=50, le=5_000)] = 370.0
    leave: FleetLeave | None = None


# ------------------------------------------------------------------------------------- scenario
# JSBSim's names for its Cessna 172 models -> this repository's aircraft folders.
ENCOUNTER_AIRCRAFT = {"c172x": "ga_c172", "c172p": "ga_c172"}


class Encounters(Section):
    """Pairwise encounters drawn from a statistical encounter model (docs/scenario.md,
    "encounters"): episode i of `uavxai evaluate` flies encounter i."""

    model: Literal["mitll_uncor"] = "mitll_uncor"
    parameters: Annotated[str, Field(min_length=1, max_length=4096)] | None = None
    intruder_aircraft: AircraftName = "ga_c172"
    importance: Literal["none", "nmac"] = "nmac"
    duration_s: Annotated[int, Field(ge=10, le=3600)] = 120
    tca_window_s: tuple[Annotated[int, Field(ge=0, le=3600)],
                        Annotated[int, Field(ge=0, le=3600)]] = (45, 75)
    hmd_max_m: Annotated[float, Field(ge=152.4, le=100_000)] = 1852.0
    vmd_max_m: Annotated[float, Field(ge=30.48, le=10_000)] = 152.4
    hmd_nominal: Literal["uniform", "disc"] = "uniform"
    intruder_floor_m: Annotated[float, Field(ge=0, le=MAX_HEIGHT_M)] = 30.0

    @field_validator("intruder_aircraft")
    @classmethod
    def _slug(cls, v: str) -> str:
        return check_slug(v, "encounters.intruder_aircraft")

    @field_validator("parameters")
    @classmethod
    def _file(cls, v: str | None) -> str | None:
        if v is not None and not Path(v).expanduser().is_file():
            raise ValueError(f"encounters.parameters: no such file {v!r}")
        return v

    @model_validator(mode="after")
    def _window(self) -> Encounters:
        lo, hi = self.tca_window_s
        if not lo <= hi < self.duration_s:
            raise ValueError(
                f"encounters.tca_window_s {list(self.tca_window_s)} must be [min, max] with "
                f"min <= max < duration_s ({self.duration_s})"
            )
        return self

    @property
    def aircraft(self) -> str:
        """The aircraft folder that flies the intruders (JSBSim's c172x is ga_c172)."""
        return ENCOUNTER_AIRCRAFT.get(self.intruder_aircraft, self.intruder_aircraft)
