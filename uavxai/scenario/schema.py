"""The scenario schema: every section's typed model with its defaults and bounds, the checks
across fields (world bounds, airspeeds, timing, channel ranges), and the clock's timing rule.

The reference of every key (default, unit, allowed values) is docs/scenario.md; a test checks
that it names every key of these models. Every model forbids unknown keys, and no value is
coerced from another type (text is never a number).
"""

from __future__ import annotations

import math
import re
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationInfo,
    field_validator,
    model_validator,
)

from uavxai.errors import UserError, short_repr
from uavxai.paths import aircraft_dir
from uavxai.scenario.aircraft import aircraft_speed_range
from uavxai.scenario.messages import printable, short_value
from uavxai.vocabulary import (
    ACTION_SETS,
    CHANNEL_MODEL_NAMES,
    CHANNEL_MODELS,
    CONFLICT_VOLUMES,
    RISK_MODELS,
    SERVICE_PLANNERS,
    action_set_problem,
    avoidance_planners,
)

# Distances are bounded so that no arithmetic downstream overflows or loses every digit of a
# metre (1e6 m = 1000 km, far beyond any flight area of this simulator).
MAX_M = 1.0e6
PositiveFloat = Annotated[float, Field(gt=0, le=MAX_M, allow_inf_nan=False)]
Finite = Annotated[float, Field(ge=-MAX_M, le=MAX_M, allow_inf_nan=False)]
Probability = Annotated[float, Field(ge=0, le=1, allow_inf_nan=False)]
MAX_HEIGHT_M = 20_000.0  # above the ground; JSBSim's standard atmosphere is valid far above
MAX_INTRUDERS = 500
MAX_USERS = 64
_SLUG = re.compile(r"[A-Za-z0-9_.-]+")


def check_slug(value: str, what: str) -> str:
    """A name that becomes a folder name: letters, digits, '-', '_', '.'; not '.' or '..'."""
    if not _SLUG.fullmatch(value) or value in (".", ".."):
        raise ValueError(
            f"{what} must be a plain name of letters, digits, '-', '_' and '.' (it names a "
            "folder), not '.' or '..'"
        )
    return value


def _ordered(value: tuple[float, float], what: str) -> tuple[float, float]:
    lo, hi = value
    if not lo < hi:
        raise ValueError(f"{what} must be [min, max] with min < max, got [{lo}, {hi}]")
    return value


def _admits(annotation: Any, kind: type) -> bool:
    """Whether a field's type accepts a value of ``kind`` (str or bool) as it is."""
    if annotation is kind or annotation is Any:
        return True
    if kind is str and annotation is Path:
        return True
    origin = typing.get_origin(annotation)
    if origin is Literal:
        return any(isinstance(v, kind) for v in typing.get_args(annotation))
    if origin is Annotated:
        return _admits(typing.get_args(annotation)[0], kind)
    return any(_admits(a, kind) for a in typing.get_args(annotation))


def _holds_sections(annotation: Any) -> bool:
    """Whether ``annotation`` (a list's, say) admits a section (a model) anywhere inside."""
    if isinstance(annotation, type) and issubclass(annotation, BaseModel):
        return True
    return any(_holds_sections(a) for a in typing.get_args(annotation))


def _strict_scalars(value: Any, annotation: Any) -> None:
    """Refuse what pydantic's lax mode would coerce: text for a number or a boolean ('9' -> 9,
    'yes' -> true) and booleans or numbers for one another (true -> 1, 1 -> true)."""
    if isinstance(value, dict):
        return  # a nested section: its own model checks its fields
    if isinstance(value, list | tuple):
        if _holds_sections(annotation):
            return  # a list of sections: each item's model checks it, and says what it is
        for item in value:
            _strict_scalars(item, annotation)
        return
    if isinstance(value, str) and not _admits(annotation, str):
        raise ValueError(
            "text where a number or true/false belongs; write it without quotes (text is never "
            "converted)"
        )
    if isinstance(value, bool) and not _admits(annotation, bool):
        raise ValueError("a boolean where a number belongs")
    if isinstance(value, int | float) and not isinstance(value, bool) and annotation is bool:
        raise ValueError("a number where true or false belongs")


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)

    @field_validator("*", mode="before")
    @classmethod
    def _no_coercion(cls, value: Any, info: ValidationInfo) -> Any:
        field = cls.model_fields[info.field_name]
        _strict_scalars(value, field.annotation)
        return value


# --------------------------------------------------------------------------------------- world
class Origin(_Model):
    # the local ENU frame is a tangent plane: near the poles it collapses, so |lat| <= 85
    lat_deg: Annotated[float, Field(ge=-85, le=85)] = 34.1230
    lon_deg: Annotated[float, Field(ge=-180, le=180)] = 108.8370
    alt_m: Annotated[float, Field(ge=-500, le=9000)] = 400.0


class DynamicsConfig(_Model):
    """How the co-simulation steps (docs/scenario.md)."""

    rate_hz: Annotated[float, Field(ge=30, le=1000)] = 120.0  # JSBSim integration rate
    trajectory_hz: Annotated[float, Field(ge=1, le=120)] = 10.0  # rows of trajectory.csv


class World(_Model):
    x: tuple[Finite, Finite] = (0.0, 2000.0)
    y: tuple[Finite, Finite] = (0.0, 2000.0)
    h: tuple[Finite, Finite] = (50.0, 300.0)
    origin: Origin = Origin()

    @field_validator("x", "y")
    @classmethod
    def _xy(cls, v: tuple[float, float], info: Any) -> tuple[float, float]:
        return _ordered(v, f"world.{info.field_name}")

    @field_validator("h")
    @classmethod
    def _h(cls, v: tuple[float, float]) -> tuple[float, float]:
        _ordered(v, "world.h")
        if v[0] <= 0:
            raise ValueError(f"world.h must be above the ground (min > 0 m), got [{v[0]}, {v[1]}]")
        if v[1] > MAX_HEIGHT_M:
            raise ValueError(f"world.h must stay below {MAX_HEIGHT_M:g} m, got [{v[0]}, {v[1]}]")
        return v

    def contains(self, x: float, y: float, h: float | None = None) -> bool:
        ok = self.x[0] <= x <= self.x[1] and self.y[0] <= y <= self.y[1]
        return ok and (h is None or self.h[0] <= h <= self.h[1])


# --------------------------------------------------------------------------------------- comms
class Region(_Model):
    x: tuple[Finite, Finite] = (750.0, 1250.0)
    y: tuple[Finite, Finite] = (750.0, 1250.0)

    @field_validator("x", "y")
    @classmethod
    def _ordered(cls, v: tuple[float, float], info: Any) -> tuple[float, float]:
        return _ordered(v, f"region.{info.field_name}")


WalkSpeed = Annotated[float, Field(ge=0, le=50, allow_inf_nan=False)]
PauseS = Annotated[float, Field(ge=0, le=86_400, allow_inf_nan=False)]


def _number_or_range(v: Any, what: str) -> Any:
    """One number (a fixed value) or ``[min, max]`` with min <= max, as uavxai.comms.mobility
    takes them."""
    if isinstance(v, tuple) and v[0] > v[1]:
        raise ValueError(f"{what} must be a number or [min, max] with min <= max")
    return v


class Mobility(_Model):
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


class Users(_Model):
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


class Comms(_Model):
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


def _checkpoint_exists(value: str | None, what: str) -> str | None:
    """A checkpoint named in the scenario must exist (relative paths were made absolute
    against the scenario's folder by :func:`load_scenario`)."""
    if value is None:
        return value
    if "\x00" in value:
        raise ValueError(f"{what} contains a NUL byte")
    try:
        exists = Path(value).is_file()
    except OSError as exc:  # e.g. a name longer than the file system allows
        raise ValueError(f"cannot look up {short_value(value)} ({exc.strerror})") from None
    if not exists:
        raise ValueError(
            f"{printable(value, 200)}: no such file; give the model.pt written by `uavxai "
            "train` (relative paths are taken from the scenario file's folder), or null for the "
            "shipped model"
        )
    return value


class Service(_Model):
    planner: Literal[SERVICE_PLANNERS] = "d3qn"  # type: ignore[valid-type]
    checkpoint: Annotated[str, Field(max_length=4096)] | None = None
    steps: Annotated[int, Field(ge=1, le=100_000)] = 100
    step_m: Annotated[float, Field(gt=0, le=500)] = 10.0
    platform: Literal["orbit", "hover"] = "orbit"
    replan_s: Annotated[float, Field(gt=0, le=86_400)] | None = None

    @field_validator("checkpoint")
    @classmethod
    def _ckpt(cls, v: str | None) -> str | None:
        return _checkpoint_exists(v, "service.checkpoint")


# ------------------------------------------------------------------------------------- aircraft
class Start(_Model):
    x: Finite = 100.0
    y: Finite = 100.0
    h: Finite = 120.0
    heading_deg: Annotated[float, Field(ge=-360, le=360)] = 45.0
    speed_mps: Annotated[float, Field(gt=0, le=100)] = 20.0


AircraftName = Annotated[str, Field(min_length=1, max_length=100)]


class Ownship(_Model):
    aircraft: AircraftName = "uav_fw"
    start: Start = Start()
    goal: tuple[Finite, Finite, Finite] | None = None

    @field_validator("aircraft")
    @classmethod
    def _slug(cls, v: str) -> str:
        return check_slug(v, "ownship.aircraft")


class IntruderSpec(_Model):
    x: Finite
    y: Finite
    h: Finite
    heading_deg: Annotated[float, Field(ge=-360, le=360)]
    speed_mps: Annotated[float, Field(gt=0, le=100)]
    behaviour: Literal["straight", "random_turns", "goal_seeking"] | None = None


# alias: the field below is called `list`; capped like `count`
IntruderList = Annotated[list[IntruderSpec], Field(max_length=MAX_INTRUDERS)]


class Intruders(_Model):
    count: Annotated[int, Field(ge=0, le=MAX_INTRUDERS)] = 20
    aircraft: AircraftName = "uav_fw"
    behaviour: Literal["straight", "random_turns", "goal_seeking"] = "straight"
    speed_mps: tuple[PositiveFloat, PositiveFloat] = (15.0, 30.0)
    altitude_m: tuple[PositiveFloat, PositiveFloat] = (100.0, 140.0)
    min_start_distance_m: Annotated[float, Field(ge=0, le=MAX_M)] = 300.0
    list: IntruderList | None = None
    flow: Literal["replace", "none"] = "replace"

    @field_validator("aircraft")
    @classmethod
    def _slug(cls, v: str) -> str:
        return check_slug(v, "intruders.aircraft")

    @field_validator("speed_mps", "altitude_m")
    @classmethod
    def _range(cls, v: tuple[float, float], info: Any) -> tuple[float, float]:
        if v[0] > v[1]:
            raise ValueError(f"intruders.{info.field_name} must be [min, max] with min <= max")
        return v

    @property
    def n(self) -> int:
        return len(self.list) if self.list is not None else self.count


# ------------------------------------------------------------------------------------ avoidance
class MCTSConfig(_Model):
    simulations: Annotated[int, Field(ge=1, le=100_000)] = 200
    depth: Annotated[int, Field(ge=1, le=8)] = 4
    c: Annotated[float, Field(ge=0, le=100)] = 1.0
    action_hold_s: Annotated[float, Field(gt=0, le=60)] = 4.0
    # How far ahead the tree planners cover what an intruder could do by banking anywhere
    # within its limit (uavxai.avoidance.model.intruder_margin); 0: only its estimated turn.
    # mvp resolves without it; only the option separations its explanations quote use it.
    # 4 s rather than 3 s (the default until issue 11's last tables): in JSBSim with moderate
    # turbulence it meets the collision goal, at a cost in goal rate among 40 intruders
    # (docs/results/README.md).
    reach_horizon_s: Annotated[float, Field(ge=0, le=60)] = 4.0
    # How far the ownship strays from the tree planners' model 10 s ahead (1 sigma per axis,
    # growing as t^1.5), added to the intruders' track uncertainty (uavxai.avoidance.model.
    # intruder_margin); 0: the model's path is taken as flown. docs/scenario.md has the values
    # measured in JSBSim (benchmarks/studies/bench_own_model.py) and what they cost.
    own_error_10s_m: Annotated[float, Field(ge=0, le=1000)] = 0.0
    # How far ahead a track's velocity error grows the separation the tree planners ask of it
    # (uavxai.avoidance.model.intruder_margin); null: over the whole search. With a poor
    # picture a shorter one keeps the mission going (docs/scenario.md has what it measured).
    uncertainty_horizon_s: Annotated[float, Field(gt=0, le=60)] | None = None
    # How `mcts` / `mcts_vertical` count a track's error (issue 31): "margin", uncertainty_k
    # sigmas of it grow the separation the tree needs (a wall); "probability", the chance
    # that the error brings the intruder within d_min weights the line's value
    # (uavxai.avoidance.risk). The sphere only: refused with the conflict cylinder.
    risk: Literal[RISK_MODELS] = "margin"  # type: ignore[valid-type]


class NMAC(_Model):
    """The near-mid-air-collision cylinder that evaluations count (500 ft x 100 ft)."""

    horizontal_m: Annotated[float, Field(gt=0, le=10_000)] = 152.4
    vertical_m: Annotated[float, Field(gt=0, le=10_000)] = 30.48


class WellClear(_Model):
    """The well-clear cylinder of small UAS that evaluations count (2000 ft x 250 ft)."""

    horizontal_m: Annotated[float, Field(gt=0, le=10_000)] = 609.6
    vertical_m: Annotated[float, Field(gt=0, le=10_000)] = 76.2


class Avoidance(_Model):
    planner: Annotated[str, Field(min_length=1, max_length=40)] = "mcts"
    checkpoint: Annotated[str, Field(max_length=4096)] | None = None  # dqn / safe_dqn
    d_min_m: Annotated[float, Field(gt=0, le=10_000)] = 50.0
    goal_radius_m: Annotated[float, Field(gt=0, le=100_000)] = 50.0
    decision_period_s: Annotated[float, Field(gt=0, le=60)] = 1.0
    # The planner's processing latency: its command, planned from the picture at t, reaches
    # the autopilot at t + this (uavxai.sim.companion); 0 is the paper's instant decision.
    decision_latency_s: Annotated[float, Field(ge=0, le=60)] = 0.0
    max_steps: Annotated[int, Field(ge=1, le=100_000)] = 400
    bank_limit_deg: Annotated[float, Field(gt=0, le=60)] = 30.0
    bank_step_deg: Annotated[float, Field(gt=0, le=60)] = 10.0
    accel_mps2: Annotated[float, Field(ge=0, le=10)] = 1.0
    speed_mps: tuple[PositiveFloat, PositiveFloat] = (12.0, 30.0)
    mcts: MCTSConfig = MCTSConfig()
    actions: Literal[tuple(ACTION_SETS)] = "paper"  # type: ignore[valid-type]
    nmac: NMAC = NMAC()
    well_clear: WellClear = WellClear()
    # The tree's conflict volume around each intruder (uavxai.avoidance.model): a sphere of
    # d_min_m, or a cylinder of radius d_min_m and a half-height of its own (PlannerConfig).
    conflict_volume: Literal[CONFLICT_VOLUMES] = "sphere"  # type: ignore[valid-type]

    @field_validator("planner")
    @classmethod
    def _planner(cls, v: str) -> str:
        names = avoidance_planners()
        if v not in names:
            raise ValueError(f"planner {short_repr(v)} is not one of {', '.join(names)}")
        return v

    @field_validator("speed_mps")
    @classmethod
    def _speed(cls, v: tuple[float, float]) -> tuple[float, float]:
        return _ordered(v, "avoidance.speed_mps")

    @field_validator("checkpoint")
    @classmethod
    def _ckpt(cls, v: str | None) -> str | None:
        return _checkpoint_exists(v, "avoidance.checkpoint")

    @model_validator(mode="after")
    def _steps(self) -> Avoidance:
        if self.bank_step_deg > self.bank_limit_deg:
            raise ValueError(
                f"bank_step_deg ({self.bank_step_deg}) must not exceed bank_limit_deg "
                f"({self.bank_limit_deg})"
            )
        problem = action_set_problem(self.planner, self.actions)
        if problem:
            raise ValueError(problem)
        if self.mcts.risk == "probability" and self.conflict_volume != "sphere":
            raise ValueError(
                "avoidance.mcts.risk: probability needs avoidance.conflict_volume: sphere "
                "(the chance of losing separation is worked out for a sphere of d_min_m)"
            )
        return self


# --------------------------------------------------------------------------------------- bridge
class GroundStation(_Model):
    """A ground station allowed to command: its MAVLink system id and its host's address."""

    system_id: Annotated[int, Field(ge=1, le=255)] = 255
    address: Annotated[str, Field(min_length=1, max_length=253)] = "127.0.0.1"

    @field_validator("address")
    @classmethod
    def _address(cls, v: str) -> str:
        import ipaddress

        try:
            return str(ipaddress.ip_address(v))
        except ValueError:
            raise ValueError(
                f"address must be an IP address (as the ground station's datagrams come "
                f"from, e.g. 127.0.0.1), got {v!r}"
            ) from None


class Bridge(_Model):
    mavlink: Annotated[str, Field(max_length=500)] | None = None
    system_id: Annotated[int, Field(ge=1, le=255)] = 1
    signing_key_hex: str | None = None
    command_timeout_s: Annotated[float, Field(gt=0, le=600)] = 3.0  # failsafe: wings level
    # who may command without a signing key (none by default); with a key, signed commands
    ground_stations: Annotated[list[GroundStation], Field(max_length=16)] = []
    tlog: bool = True  # every frame in and out to RUN/link.tlog (uavxai run with a link)

    @model_validator(mode="before")
    @classmethod
    def _removed(cls, data: Any) -> Any:
        if isinstance(data, dict) and "override_s" in data:
            raise ValueError(
                "bridge.override_s was removed: an operator's command no longer switches "
                "avoidance off for a while, it sets where the ownship goes and avoidance "
                "stays on (see 'Operating from a ground station' in the README); delete the key"
            )
        return data

    @field_validator("signing_key_hex")
    @classmethod
    def _key(cls, v: str | None) -> str | None:
        if v is None:
            return v
        try:
            ok = len(v) == 64 and bytes.fromhex(v) is not None
        except ValueError:
            ok = False
        if not ok:
            raise ValueError("signing_key_hex must be exactly 64 hexadecimal digits (32 bytes)")
        return v.lower()

    @field_validator("mavlink")
    @classmethod
    def _url(cls, v: str | None) -> str | None:
        if v is not None:
            check_mavlink_url(v)
        return v


class Log(_Model):
    rerun: bool = True


# ---------------------------------------------------------------------------------- environment
class Wind(_Model):
    speed_mps: Annotated[float, Field(ge=0, le=100)] = 0.0
    from_deg: Annotated[float, Field(ge=0, le=360)] = 270.0  # blows FROM, clockwise from north


class Environment(_Model):
    wind: Wind = Wind()
    turbulence: Literal["none", "light", "moderate", "severe"] = "none"


# --------------------------------------------------------------------------------- surveillance
class Sensor(_Model):
    range_m: Annotated[float, Field(ge=0, le=MAX_M)] = 1000.0
    fov_deg: Annotated[float, Field(ge=0, le=360)] = 220.0
    sigma_m: Annotated[float, Field(ge=0, le=10_000)] = 10.0


class Surveillance(_Model):
    model: Literal["adsb", "truth"] = "adsb"
    rate_hz: Annotated[float, Field(gt=0, le=100)] = 1.0
    nacp: Annotated[int, Field(ge=5, le=11)] = 10  # DO-260B categories with a bound
    nacv: Annotated[int, Field(ge=1, le=4)] = 2
    latency_s: Annotated[float, Field(ge=0, le=60)] = 0.5
    dropout: Annotated[float, Field(ge=0, lt=1)] = 0.05
    noncooperative: Probability = 0.0
    sensor: Sensor | None = Sensor()  # null: no onboard sensor
    preroll_s: Annotated[float, Field(ge=0, le=600)] = 10.0  # listening before t = 0
    # the filter of each track: ekf (one coordinated turn, its rate estimated) or imm
    # (straight, left and right turns mixed; uavxai.surveillance.imm)
    tracker: Literal["ekf", "imm"] = "ekf"


# ------------------------------------------------------------------------------------- operator
OPERATOR_MODES = ("AUTO", "GUIDED", "LOITER", "RTL")


class OrbitAim(_Model):
    x: Finite
    y: Finite
    h: Finite
    radius_m: Annotated[float, Field(ge=1, le=MAX_M)] = 150.0
    clockwise: bool = True


class OperatorCommandSpec(_Model):
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


class Operator(_Model):
    """A scripted operator: timed ground-station commands, sent as MAVLink frames through the
    bridge's own decoder (BlueSky's timed stack commands, for a pilot in the loop)."""

    system_id: Annotated[int, Field(ge=1, le=255)] = 255
    commands: Annotated[list[OperatorCommandSpec], Field(max_length=1000)] = []


# -------------------------------------------------------------------------------------- mission
class Mission(_Model):
    service_s: Annotated[float, Field(ge=0, le=86_400)] = 300.0
    return_home: bool = True
    orbit_radius_m: Annotated[float, Field(gt=0, le=10_000)] | None = None  # null: from bank


# ------------------------------------------------------------------------------------- scenario
# JSBSim's names for its Cessna 172 models -> this repository's aircraft folders.
ENCOUNTER_AIRCRAFT = {"c172x": "ga_c172", "c172p": "ga_c172"}


class Encounters(_Model):
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


class Scenario(_Model):
    name: Annotated[str, Field(min_length=1, max_length=200)]
    seed: Annotated[int, Field(ge=0, le=2**31 - 1)] = 0
    world: World = World()
    dynamics: DynamicsConfig = DynamicsConfig()
    comms: Comms = Comms()
    service: Service = Service()
    ownship: Ownship = Ownship()
    intruders: Intruders = Intruders()
    avoidance: Avoidance = Avoidance()
    bridge: Bridge = Bridge()
    log: Log = Log()
    environment: Environment = Environment()
    surveillance: Surveillance = Surveillance()
    mission: Mission = Mission()
    operator: Operator = Operator()
    encounters: Encounters | None = None

    @field_validator("name")
    @classmethod
    def _name(cls, v: str) -> str:
        return check_slug(v, "name")

    @model_validator(mode="after")
    def _timing(self) -> Scenario:
        """What the simulation clock (uavxai.sim.clock) and the bridge's failsafe would refuse,
        refused here already so that `validate` says it."""
        clock_ticks(self.dynamics, self.avoidance)
        period = self.avoidance.decision_period_s
        timeout = self.bridge.command_timeout_s
        if not timeout > period:
            raise ValueError(
                f"bridge.command_timeout_s = {timeout:g} s must be longer than "
                f"avoidance.decision_period_s = {period:g} s, or the failsafe overrides the "
                "planner between its decisions"
            )
        return self

    @model_validator(mode="after")
    def _geometry(self) -> Scenario:
        w = self.world
        s = self.ownship.start
        if not w.contains(s.x, s.y, s.h):
            raise ValueError(
                f"ownship.start ({s.x}, {s.y}, {s.h}) lies outside the world bounds "
                f"x {list(w.x)}, y {list(w.y)}, h {list(w.h)}"
            )
        if self.ownship.goal is not None and not w.contains(*self.ownship.goal):
            raise ValueError(
                f"ownship.goal {list(self.ownship.goal)} lies outside the world bounds"
            )
        r = self.comms.users.region
        if not (w.x[0] <= r.x[0] and r.x[1] <= w.x[1] and w.y[0] <= r.y[0] and r.y[1] <= w.y[1]):
            raise ValueError(
                f"comms.users.region x {list(r.x)}, y {list(r.y)} must lie inside the world "
                f"x {list(w.x)}, y {list(w.y)}"
            )
        for i, spec in enumerate(self.intruders.list or []):
            if not w.contains(spec.x, spec.y, spec.h):
                raise ValueError(
                    f"intruders.list.{i} at ({spec.x:g}, {spec.y:g}, {spec.h:g}) lies outside the "
                    f"world bounds x {list(w.x)}, y {list(w.y)}, h {list(w.h)}"
                )
        lo, hi = self.intruders.altitude_m
        if self.intruders.list is None and not (w.h[0] <= lo and hi <= w.h[1]):
            raise ValueError(
                f"intruders.altitude_m = [{lo:g}, {hi:g}] must lie inside world.h {list(w.h)}"
            )
        for name in {self.ownship.aircraft, self.intruders.aircraft}:
            if not (aircraft_dir() / name / f"{name}.xml").is_file():
                known = sorted(
                    p.name for p in aircraft_dir().iterdir() if (p / f"{p.name}.xml").is_file()
                )
                raise ValueError(
                    f"aircraft '{name}' is not a folder under aircraft/; known: {known}"
                )
        self._flyable()
        self._encounters()
        self._channel_range()
        return self

    def _channel_range(self) -> None:
        """A 3GPP channel holds for some UAV heights and horizontal distances only; the UAV
        flies (and is served) anywhere in the world, the users stay in their region."""
        valid = CHANNEL_MODELS[self.comms.channel]
        if valid is None:
            return
        w, r = self.world, self.comms.users.region
        what = f"comms.channel {self.comms.channel} ({valid.standard})"
        if not (valid.h_min_m < w.h[0] and w.h[1] <= valid.h_max_m):
            raise ValueError(
                f"{what} holds for UAV heights {valid.h_min_m:g} m < h <= {valid.h_max_m:g} m "
                f"and world.h is {list(w.h)}; allowed: world.h inside that range (below it "
                "the standard falls back to terrestrial formulas that need a base-station mast)"
            )
        dx = max(r.x[1] - w.x[0], w.x[1] - r.x[0])
        dy = max(r.y[1] - w.y[0], w.y[1] - r.y[0])
        if math.hypot(dx, dy) > valid.d2d_max_m:
            raise ValueError(
                f"{what} holds for horizontal distances up to {valid.d2d_max_m:g} m, and a UAV "
                f"in world x {list(w.x)}, y {list(w.y)} can be {math.hypot(dx, dy):.0f} m from a "
                f"user in comms.users.region x {list(r.x)}, y {list(r.y)}; allowed: a world "
                f"whose farthest point lies within {valid.d2d_max_m:g} m of the region"
            )

    def _encounters(self) -> None:
        """An encounter scenario flies one sampled intruder per episode, to a fixed goal."""
        e = self.encounters
        if e is None:
            return
        if self.intruders.list is not None or self.intruders.flow != "none":
            raise ValueError(
                "encounters: each episode's intruder is the sampled encounter's; set "
                "intruders.flow: none and no intruders.list"
            )
        if self.ownship.goal is None:
            raise ValueError(
                "encounters: set ownship.goal (the ownship's straight path from its start to "
                "the goal is the path the encounter is placed against)"
            )
        if not (aircraft_dir() / e.aircraft / f"{e.aircraft}.xml").is_file():
            known = sorted(
                p.name for p in aircraft_dir().iterdir() if (p / f"{p.name}.xml").is_file()
            )
            raise ValueError(
                f"encounters.intruder_aircraft '{e.intruder_aircraft}' is not a folder under "
                f"aircraft/ (known: {known}; c172x and c172p mean ga_c172)"
            )
        start, goal = self.ownship.start, self.ownship.goal
        if math.dist((start.x, start.y), goal[:2]) < 1.0:
            raise ValueError("encounters: ownship.goal must lie away from ownship.start")

    def _flyable(self) -> None:
        """Speeds the aircraft can fly, from the same numbers JSBSim reads (the autopilot's
        ap/speed-min-mps and ap/speed-max-mps, see uavxai.dynamics.world._check_speed)."""
        own, intr = self.ownship.aircraft, self.intruders.aircraft
        lo, hi = aircraft_speed_range(own)
        s = self.ownship.start.speed_mps
        if not lo <= s <= hi:
            raise ValueError(
                f"ownship.start.speed_mps = {s:g} m/s: aircraft '{own}' flies between {lo:g} and "
                f"{hi:g} m/s"
            )
        a = self.avoidance.speed_mps
        if max(lo, a[0]) >= min(hi, a[1]):
            raise ValueError(
                f"avoidance.speed_mps = {list(a)}: aircraft '{own}' flies between {lo:g} and "
                f"{hi:g} m/s; the two ranges must overlap"
            )
        lo, hi = aircraft_speed_range(intr)
        for i, spec in enumerate(self.intruders.list or []):
            if not lo <= spec.speed_mps <= hi:
                raise ValueError(
                    f"intruders.list.{i}.speed_mps = {spec.speed_mps:g} m/s: aircraft '{intr}' "
                    f"flies between {lo:g} and {hi:g} m/s"
                )
        r = self.intruders.speed_mps
        if self.intruders.list is None and not (lo <= r[0] and r[1] <= hi):
            raise ValueError(
                f"intruders.speed_mps = {list(r)}: aircraft '{intr}' flies between {lo:g} and "
                f"{hi:g} m/s; the drawn speeds must lie inside"
            )
        own_lo, _ = aircraft_speed_range(own)
        wind = self.environment.wind.speed_mps
        if wind >= own_lo:
            raise ValueError(
                f"environment.wind.speed_mps = {wind:g} m/s is not below the slowest airspeed of "
                f"aircraft '{own}' ({own_lo:g} m/s): flying slowly it would be blown backwards; "
                f"allowed: below {own_lo:g} m/s"
            )
        w = self.world
        r_orbit = self.mission.orbit_radius_m
        room = min(w.x[1] - w.x[0], w.y[1] - w.y[0]) / 2
        if r_orbit is not None and r_orbit > room:
            raise ValueError(
                f"mission.orbit_radius_m = {r_orbit:g} m: the orbit does not fit in the world "
                f"(x {list(w.x)}, y {list(w.y)}); allowed: at most {room:g} m, half the world's "
                "narrower side"
            )
        sv = self.intruders
        any_intruders = bool(sv.list) if sv.list is not None else sv.count > 0
        if (
            any_intruders
            and self.surveillance.noncooperative >= 1.0
            and self.surveillance.sensor is None
        ):
            raise ValueError(
                "surveillance.noncooperative = 1 (no intruder broadcasts ADS-B) with "
                "surveillance.sensor null (no onboard sensor): the planner would see no intruder "
                "at all; give a sensor, or make noncooperative less than 1"
            )

    def with_seed(self, seed: int) -> Scenario:
        return self.model_copy(update={"seed": int(seed)})


_TICK_TOL = 1e-6


def _whole_ticks(seconds: float, tick_s: float) -> int | None:
    """``seconds`` as a whole number (>= 1) of ``tick_s``, or None (the clock's rule)."""
    n = round(seconds / tick_s)
    if n < 1 or abs(n * tick_s - seconds) > _TICK_TOL * max(1.0, seconds):
        return None
    return n


def clock_ticks(dynamics: DynamicsConfig, avoidance: Avoidance) -> tuple[int, int, int]:
    """(ticks per sample, per decision, of latency) of the simulation clock
    (:class:`uavxai.sim.clock.Clock`), time counted in whole integrator ticks of
    1 / ``dynamics.rate_hz``; ValueError naming the setting when a period is not a whole number
    of ticks (a 100 Hz integrator with 30 Hz samples would decide every 0.9 s while the
    planner assumes 1 s), the decision period not a whole number of samples, or the latency
    not a whole number of samples shorter than the decision period. The one rule: the schema
    refuses with it at load, and the clock counts with it."""
    rate, traj = dynamics.rate_hz, dynamics.trajectory_hz
    period = avoidance.decision_period_s
    tick = 1.0 / rate
    sample = _whole_ticks(1.0 / traj, tick)
    if sample is None:
        raise ValueError(
            f"dynamics.rate_hz ({rate:g}) must be a whole multiple of dynamics.trajectory_hz "
            f"({traj:g}), e.g. 120 and 10"
        )
    decision = _whole_ticks(period, tick)
    if decision is None:
        raise ValueError(
            f"avoidance.decision_period_s = {period:g} s must be a whole number (>= 1) of "
            f"integrator steps of 1 / dynamics.rate_hz = {tick:g} s"
        )
    if decision % sample:
        raise ValueError(
            f"avoidance.decision_period_s = {period:g} s must be a whole number of "
            f"trajectory samples (1 / dynamics.trajectory_hz = {1 / traj:g} s)"
        )
    latency = avoidance.decision_latency_s
    lag = _whole_ticks(latency, tick) if latency > 0 else 0
    if lag is None or lag % sample or not latency < period:
        raise ValueError(
            f"avoidance.decision_latency_s = {latency:g} s must be 0 or a whole number of "
            f"trajectory samples (1 / dynamics.trajectory_hz = {1 / traj:g} s) shorter than "
            f"avoidance.decision_period_s = {period:g} s"
        )
    return sample, decision, lag


def check_mavlink_url(url: str) -> str:
    """Check the form of a pymavlink connection string (the bridge's rule, one place)."""
    from uavxai.link_url import check_link

    try:
        check_link(url)
    except UserError as exc:
        raise ValueError(str(exc)) from None
    return url
