"""The scenario schema, one module a group of sections (their layers, top first, are checked by
import-linter: "schema rooms" in pyproject.toml):

- ``root``: the :class:`Scenario` and its checks across sections, the clock's timing rule;
- ``world``: world, dynamics, comms (users), service;
- ``flight``: ownship, intruders, avoidance (uavxai.avoidance.settings derives PlannerConfig
  from it);
- ``links``: bridge, log, environment, surveillance;
- ``operations``: operator, mission, fleet, encounters;
- ``base``: what every section shares (the base model, bounded numbers, names).

The reference of every key (default, unit, allowed values) is docs/scenario.md; a test checks
that it names every key of these models. Every model forbids unknown keys, and no value is
coerced from another type (text is never a number).
"""

from uavxai.scenario.schema.base import (
    MAX_HEIGHT_M,
    MAX_INTRUDERS,
    MAX_M,
    MAX_USERS,
    AircraftName,
    Finite,
    PositiveFloat,
    Probability,
    Section,
    check_slug,
)
from uavxai.scenario.schema.flight import (
    NMAC,
    Avoidance,
    IntruderList,
    Intruders,
    IntruderSpec,
    MCTSConfig,
    Ownship,
    Start,
    WellClear,
)
from uavxai.scenario.schema.links import (
    Bridge,
    Environment,
    GroundStation,
    Log,
    Sensor,
    Surveillance,
    Wind,
    check_mavlink_url,
)
from uavxai.scenario.schema.operations import (
    ENCOUNTER_AIRCRAFT,
    MAX_FLEET,
    OPERATOR_MODES,
    Encounters,
    Fleet,
    FleetLeave,
    Mission,
    Operator,
    OperatorCommandSpec,
    OrbitAim,
)
from uavxai.scenario.schema.root import Scenario, clock_ticks
from uavxai.scenario.schema.world import (
    Comms,
    DynamicsConfig,
    Mobility,
    Origin,
    PauseS,
    Region,
    Service,
    Users,
    WalkSpeed,
    World,
)

__all__ = [
    "ENCOUNTER_AIRCRAFT",
    "MAX_HEIGHT_M",
    "MAX_INTRUDERS",
    "MAX_M",
    "MAX_USERS",
    "NMAC",
    "OPERATOR_MODES",
    "AircraftName",
    "Avoidance",
    "Bridge",
    "Comms",
    "DynamicsConfig",
    "Encounters",
    "Environment",
    "Finite",
    "GroundStation",
    "IntruderList",
    "IntruderSpec",
    "Intruders",
    "Log",
    "MCTSConfig",
    "Fleet",
    "FleetLeave",
    "MAX_FLEET",
    "Mission",
    "Mobility",
    "Operator",
    "OperatorCommandSpec",
    "OrbitAim",
    "Origin",
    "Ownship",
    "PauseS",
    "PositiveFloat",
    "Probability",
    "Region",
    "Scenario",
    "Section",
    "Sensor",
    "Service",
    "Start",
    "Surveillance",
    "Users",
    "WalkSpeed",
    "WellClear",
    "Wind",
    "World",
    "check_mavlink_url",
    "check_slug",
    "clock_ticks",
]
