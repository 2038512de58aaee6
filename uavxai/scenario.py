"""Scenario files: the typed schema of SPEC §3, its defaults, and friendly validation errors.

Every model forbids unknown keys; a misspelt key is reported with the nearest valid one.
Units are SI; only fields ending in ``_deg`` are degrees.
"""

from __future__ import annotations

import difflib
import math
from pathlib import Path
from typing import Annotated, Any, Literal

import yaml
from pydantic import (
    BaseModel,
    ConfigDict,
    Field,
    ValidationError,
    field_validator,
    model_validator,
)

from uavxai.errors import ScenarioError, UserError
from uavxai.paths import aircraft_dir

PositiveFloat = Annotated[float, Field(gt=0, allow_inf_nan=False)]
Finite = Annotated[float, Field(allow_inf_nan=False)]


def _ordered(value: tuple[float, float], what: str) -> tuple[float, float]:
    lo, hi = value
    if not lo < hi:
        raise ValueError(f"{what} must be [min, max] with min < max, got [{lo}, {hi}]")
    return value


class _Model(BaseModel):
    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)


# --------------------------------------------------------------------------------------- world
class Origin(_Model):
    lat_deg: Annotated[float, Field(ge=-90, le=90)] = 34.1230
    lon_deg: Annotated[float, Field(ge=-180, le=180)] = 108.8370
    alt_m: Annotated[float, Field(ge=-500, le=9000)] = 400.0


class DynamicsConfig(_Model):
    """How the co-simulation steps (not in SPEC §3; added)."""

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
        return v

    def contains(self, x: float, y: float, h: float | None = None) -> bool:
        ok = self.x[0] <= x <= self.x[1] and self.y[0] <= y <= self.y[1]
        return ok and (h is None or self.h[0] <= h <= self.h[1])

    @property
    def diagonal_m(self) -> float:
        return math.dist((self.x[0], self.y[0], self.h[0]), (self.x[1], self.y[1], self.h[1]))


# --------------------------------------------------------------------------------------- comms
class Region(_Model):
    x: tuple[Finite, Finite] = (750.0, 1250.0)
    y: tuple[Finite, Finite] = (750.0, 1250.0)

    @field_validator("x", "y")
    @classmethod
    def _ordered(cls, v: tuple[float, float], info: Any) -> tuple[float, float]:
        return _ordered(v, f"region.{info.field_name}")


class Users(_Model):
    count: Annotated[int, Field(ge=1, le=64)] = 10
    positions: list[tuple[Finite, Finite]] | None = None
    region: Region = Region()

    @model_validator(mode="after")
    def _count_matches(self) -> Users:
        given = self.positions is not None and "count" in self.model_fields_set
        if given and len(self.positions) != self.count:
            raise ValueError(
                f"count is {self.count} but {len(self.positions)} positions are given; "
                "give one of them, or make them agree"
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
    qos_rate_bps: Annotated[float, Field(ge=0)] = 1.0e5
    access: Literal["shared", "ofdma"] = "shared"


class Service(_Model):
    planner: Literal["d3qn", "dqn", "random", "grid"] = "d3qn"
    checkpoint: str | None = None
    steps: Annotated[int, Field(ge=1, le=100_000)] = 100
    step_m: Annotated[float, Field(gt=0, le=500)] = 10.0


# ------------------------------------------------------------------------------------- aircraft
class Start(_Model):
    x: Finite = 100.0
    y: Finite = 100.0
    h: Finite = 120.0
    heading_deg: Annotated[float, Field(ge=-360, le=360)] = 45.0
    speed_mps: Annotated[float, Field(gt=0, le=100)] = 20.0


class Ownship(_Model):
    aircraft: str = "uav_fw"
    start: Start = Start()
    goal: tuple[Finite, Finite, Finite] | None = None


class IntruderSpec(_Model):
    x: Finite
    y: Finite
    h: Finite
    heading_deg: Annotated[float, Field(ge=-360, le=360)]
    speed_mps: Annotated[float, Field(gt=0, le=100)]
    behaviour: Literal["straight", "random_turns", "goal_seeking"] | None = None


IntruderList = list[IntruderSpec]  # alias: the field below is called `list`


class Intruders(_Model):
    count: Annotated[int, Field(ge=0, le=500)] = 20
    aircraft: str = "uav_fw"
    behaviour: Literal["straight", "random_turns", "goal_seeking"] = "straight"
    speed_mps: tuple[PositiveFloat, PositiveFloat] = (15.0, 30.0)
    altitude_m: tuple[PositiveFloat, PositiveFloat] = (100.0, 140.0)
    min_start_distance_m: Annotated[float, Field(ge=0)] = 300.0
    list: IntruderList | None = None

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


class Avoidance(_Model):
    planner: Literal["mcts", "mcts_fast", "exhaustive", "dqn", "safe_dqn", "none"] = "mcts"
    checkpoint: str | None = None  # for dqn / safe_dqn; null: the shipped model
    d_min_m: PositiveFloat = 50.0
    goal_radius_m: PositiveFloat = 50.0
    decision_period_s: Annotated[float, Field(gt=0, le=60)] = 1.0
    max_steps: Annotated[int, Field(ge=1, le=100_000)] = 400
    bank_limit_deg: Annotated[float, Field(gt=0, le=60)] = 30.0
    bank_step_deg: Annotated[float, Field(gt=0, le=60)] = 10.0
    accel_mps2: Annotated[float, Field(ge=0, le=10)] = 1.0
    speed_mps: tuple[PositiveFloat, PositiveFloat] = (12.0, 30.0)
    mcts: MCTSConfig = MCTSConfig()

    @field_validator("speed_mps")
    @classmethod
    def _speed(cls, v: tuple[float, float]) -> tuple[float, float]:
        return _ordered(v, "avoidance.speed_mps")

    @model_validator(mode="after")
    def _steps(self) -> Avoidance:
        if self.bank_step_deg > self.bank_limit_deg:
            raise ValueError(
                f"bank_step_deg ({self.bank_step_deg}) must not exceed bank_limit_deg "
                f"({self.bank_limit_deg})"
            )
        return self


# --------------------------------------------------------------------------------------- bridge
class Bridge(_Model):
    mavlink: str | None = None
    system_id: Annotated[int, Field(ge=1, le=255)] = 1
    signing_key_hex: str | None = None
    command_timeout_s: Annotated[float, Field(gt=0, le=600)] = 3.0  # failsafe: wings level

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


# ------------------------------------------------------------------------------------- scenario
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
        for spec in self.intruders.list or []:
            if not w.contains(spec.x, spec.y):
                raise ValueError(f"intruder at ({spec.x}, {spec.y}) lies outside the world bounds")
        for name in {self.ownship.aircraft, self.intruders.aircraft}:
            if not (aircraft_dir() / name / f"{name}.xml").is_file():
                known = sorted(
                    p.name for p in aircraft_dir().iterdir() if (p / f"{p.name}.xml").is_file()
                )
                raise ValueError(
                    f"aircraft '{name}' is not a folder under aircraft/; known: {known}"
                )
        return self

    def with_seed(self, seed: int) -> Scenario:
        return self.model_copy(update={"seed": int(seed)})


# ----------------------------------------------------------------------------------- loading
def check_mavlink_url(url: str) -> str:
    """Check the form of a pymavlink connection string (the bridge's rule, one place)."""
    from uavxai.bridges.link import check_link

    try:
        check_link(url)
    except UserError as exc:
        raise ValueError(str(exc)) from None
    return url


def _allowed_keys(model: type[BaseModel], loc: tuple[Any, ...]) -> list[str]:
    """The valid keys of the sub-model addressed by a validation error's location."""
    current: Any = model
    for part in loc[:-1]:
        if isinstance(part, int):
            continue
        field = getattr(current, "model_fields", {}).get(part)
        if field is None:
            return []
        ann = field.annotation
        current = _first_model(ann)
        if current is None:
            return []
    return list(getattr(current, "model_fields", {}))


def _first_model(ann: Any) -> type[BaseModel] | None:
    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann
    for arg in getattr(ann, "__args__", ()) or ():
        found = _first_model(arg)
        if found is not None:
            return found
    return None


def _describe(err: dict[str, Any]) -> str:
    loc = ".".join(str(p) for p in err["loc"])
    kind = err["type"]
    value = err.get("input")
    if kind == "extra_forbidden":
        key = str(err["loc"][-1])
        allowed = _allowed_keys(Scenario, err["loc"])
        near = difflib.get_close_matches(key, allowed, n=1, cutoff=0.5)
        hint = f" Did you mean '{near[0]}'?" if near else ""
        return f"'{loc}': unknown key.{hint} Allowed here: {', '.join(allowed)}."
    if kind == "missing":
        return f"'{loc}': required but missing."
    msg = err["msg"].removeprefix("Value error, ")
    if not loc:
        return f"{msg}."
    shown = repr(value) if not isinstance(value, dict) else "a mapping"
    if len(shown) > 80:
        shown = shown[:77] + "..."
    return f"'{loc}' = {shown}: {msg}."


def parse_scenario(data: Any, source: str = "<scenario>") -> Scenario:
    """Validate already-parsed YAML data."""
    if not isinstance(data, dict):
        kind = type(data).__name__ if data is not None else "an empty document"
        raise ScenarioError(
            f"{source}: a scenario must be a YAML mapping of keys (name, world, comms, ...), "
            f"got {kind}."
        )
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        lines = [_describe(e) for e in exc.errors()]
        raise ScenarioError(
            f"{source}: invalid scenario ({len(lines)} problem{'s' if len(lines) > 1 else ''}):\n  "
            + "\n  ".join(lines)
            + "\nSee the scenario reference in README.md (units: m, s, rad; *_deg in degrees)."
        ) from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file; raises :class:`ScenarioError` on any problem."""
    p = Path(path)
    if p.is_dir() or not p.exists():
        raise ScenarioError(f"{p}: no such scenario file (expected a .yaml file).")
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise ScenarioError(f"{p}: cannot read the scenario file ({exc}).") from None
    try:
        data = yaml.safe_load(text)
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ScenarioError(f"{p}: not valid YAML{where}: {problem}.") from None
    return parse_scenario(data, str(p))


def default_scenario(name: str = "demo", **overrides: Any) -> Scenario:
    """A scenario with every default, for tests and library users."""
    return parse_scenario({"name": name, **overrides})
