"""The flight area and the ground: `world` (bounds, origin), `dynamics` (the integrator's and
the trajectory's rates), `comms` (users, their region and mobility, the channel) and `service`
(the service-point planner)."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from uavxai.scenario.schema.base import (
    MAX_HEIGHT_M,
    MAX_USERS,
    Finite,
    Section,
    checkpoint_exists,
    ordered_pair,
)
from uavxai.vocabulary import (
    CHANNEL_MODEL_NAMES,
    CHANNEL_MODELS,
    SERVICE_PLANNERS,
)


# --------------------------------------------------------------------------------------- world
class Origin(Section):
    # the local ENU frame is a tangent plane: near the poles it collapses, so |lat| <= 85
    lat_deg: Annotated[float, Field(ge=-85, le=85)] = 34.1230
    lon_deg: Annotated[float, Field(ge=-180, le=180)] = 108.8370
    alt_m: Annotated[float, Field(ge=-500, le=9000)] = 400.0


class DynamicsConfig(Section):
    """How the co-simulation steps (docs/scenario.md)."""

    rate_hz: Annotated[float, Field(ge=30, le=1000)] = 120.0  # JSBSim integration rate
    trajectory_hz: Annotated[float, Field(ge=1, le=120)] = 10.0  # rows of trajectory.csv


class World(Section):
    x: tuple[Finite, Finite] = (0.0, 2000.0)
    y: tuple[Finite, Finite] = (0.0, 2000.0)
    h: tuple[Finite, Finite] = (50.0, 300.0)
    origin: Origin = Origin()

    @field_validator("x", "y")
    @classmethod
    def _xy(cls, v: tuple[float, float], info: Any) -> tuple[float, float]:
        return ordered_pair(v, f"world.{info.field_name}")

    @field_validator("h")
    @classmethod
    def _h(cls, v: tuple[float, float]) -> tuple[float, float]:
        ordered_pair(v, "world.h")
        if v[0] <= 0:
            raise ValueError(f"world.h must be above the ground (min > 0 m), got [{v[0]}, {v[1]}]")
        if v[1] > MAX_HEIGHT_M:
            raise ValueError(f"world.h must stay below {MAX_HEIGHT_M:g} m, got [{v[0]}, {v[1]}]")
        return v

    def contains(self, x: float, y: float, h: float | None = None) -> bool:
        ok = self.x[0] <= x <= self.x[1] and self.y[0] <= y <= self.y[1]
        return ok and (h is None or self.h[0] <= h <= self.h[1])


# --------------------------------------------------------------------------------------- comms
class Region(Section):
    x: tuple[Finite, Finite] = (750.0, 1250.0)
    y: tuple[Finite, Finite] = (750.0, 1250.0)

    @field_validator("x", "y")
    @classmethod
    def _ordered(cls, v: tuple[float, float], info: Any) -> tuple[float, float]:
        return ordered_pair(v, f"region.{info.field_name}")


WalkSpeed = Annotated[float, Field(ge=0, le=50, allow_inf_nan=False)]
PauseS = Annotated[float, Field(ge=0, le=86_400, allow_inf_nan=False)]


def _number_or_range(v: Any, what: str) -> Any:
    """One number (a fixed value) or ``[min, max]`` with min <= max, as uavxai.comms.mobility
    takes them."""
    if isinstance(v, tuple) and v[0] > v[1]:
        raise ValueError(f"{what} must be a number or [min, max] with min <= max")
    return v


class Mobility(Section):
    """How ground users move (uavxai.comms.mobility; its defaults, walking pace)."""

    model: Literal["static", "random_waypoint"] = "static"
    speed_mps: WalkSpeed | tuple[WalkSpeed, WalkSpeed] = (0.5, 1.5)
    pause_s: PauseS | tuple[PauseS, PauseS] = (0.0, 30.0)

    @field_validator("speed_mps", "pause_s")
    @classmethod
    def _range(cls, v: Any, info: Any) -> Any:
        return _number_or_range(v, f"comms.users.mobility.{info.field_name}")

    @model_validator(mode="after")
    def _walking(self) -> Mobility:
        lo = self.speed_mps if isinstance(self.speed_mps, float) else self.speed_mps[0]
        if self.model == "random_waypoint" and not lo > 0:
            raise ValueError(
                "speed_mps must be > 0 for model random_waypoint (model: static is for users "
                "who stand still)"
            )
        return self


class Users(Section):
    count: Annotated[int, Field(ge=1, le=MAX_USERS)] = 10
    positions: Annotated[
        list[tuple[Finite, Finite]], Field(min_length=1, max_length=MAX_USERS)
    ] | None = None
    region: Region = Region()
    mobility: Mobility = Mobility()

    @model_validator(mode="after")
    def _count_matches(self) -> Users:
        given = self.positions is not None and "count" in self.model_fields_set
        if given and len(self.positions) != self.count:
            raise ValueError(
                f"count is {self.count} but {len(self.positions)} positions are given; "
                "give one of them, or make them agree"
            )
        r = self.region
        for i, (x, y) in enumerate(self.positions or []):
            if not (r.x[0] <= x <= r.x[1] and r.y[0] <= y <= r.y[1]):
                # the service-point search runs inside the region: a user outside it may be
                # out of reach of every candidate point (rate 0)
                raise ValueError(
                    f"positions[{i}] = [{x:g}, {y:g}] lies outside comms.users.region "
                    f"x {list(r.x)}, y {list(r.y)}; widen the region or move the user"
                )
        return self

    @property
    def k(self) -> int:
        return len(self.positions) if self.positions is not None else self.count


class Comms(Section):
    users: Users = Users()
    carrier_ghz: Annotated[float, Field(gt=0.1, le=100)] = 2.0
    bandwidth_hz: Annotated[float, Field(gt=0, le=1e10)] = 1.0e6
    noise_dbm: Annotated[float, Field(ge=-200, le=30)] = -100.0
    environment: Literal["suburban", "urban", "dense_urban", "highrise_urban"] = "urban"
    fading: Literal["rayleigh", "rician", "none"] = "rayleigh"
    p_max_w: Annotated[float, Field(gt=0, le=1000)] = 1.0
    power_levels: Annotated[int, Field(ge=2, le=32)] = 6
    qos_rate_bps: Annotated[float, Field(ge=0, le=1e12)] = 1.0e5
    access: Literal["shared", "ofdma"] = "shared"
    channel: Literal[CHANNEL_MODEL_NAMES] = "al_hourani"  # type: ignore[valid-type]
    shadowing: bool = False

    @model_validator(mode="after")
    def _shadowing(self) -> Comms:
        """Shadowing is drawn with the fading, from a 3GPP model's sigma per LoS state."""
        if not self.shadowing:
            return self
        if CHANNEL_MODELS[self.channel] is None:
            raise ValueError(
                f"comms.shadowing: true needs a channel with a shadow-fading sigma; "
                f"comms.channel {self.channel} has none; allowed: comms.channel one of "
                f"{', '.join(n for n, v in CHANNEL_MODELS.items() if v)}, or shadowing: false"
            )
        if self.fading == "none":
            raise ValueError(
                "comms.shadowing: true is drawn with the fading, and comms.fading: none draws "
                "nothing (the fading-free mean channel); allowed: fading rayleigh or rician, or "
                "shadowing: false"
            )
        return self


class Service(Section):
    planner: Literal[SERVICE_PLANNERS] = "d3qn"  # type: ignore[valid-type]
    checkpoint: Annotated[str, Field(max_length=4096)] | None = None
    steps: Annotated[int, Field(ge=1, le=100_000)] = 100
    step_m: Annotated[float, Field(gt=0, le=500)] = 10.0
    platform: Literal["orbit", "hover"] = "orbit"
    replan_s: Annotated[float, Field(gt=0, le=86_400)] | None = None

    @field_validator("checkpoint")
    @classmethod
    def _ckpt(cls, v: str | None) -> str | None:
        return checkpoint_exists(v, "service.checkpoint")
