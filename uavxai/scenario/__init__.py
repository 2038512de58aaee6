"""Scenario files: the typed schema, its defaults, and friendly validation errors.

The reference of every key (default, unit, allowed values) is docs/scenario.md; a test checks
that it names every key of these models. Every model forbids unknown keys; a misspelt key is
reported with the nearest valid one. Units are SI; only fields ending in ``_deg`` are degrees.

Scenario files are untrusted input: the YAML loader bounds the file size, the nesting depth and
the node count with aliases expanded (a few hundred bytes of nested anchors would otherwise
expand to gigabytes), refuses duplicate keys, and every number the schema accepts is finite and
bounded, so that a bad file ends in :class:`ScenarioError` within milliseconds.

The package, one job a module (the layers, top first, are checked by import-linter):

- ``loader``: a file read as untrusted input (bounded size, bounded YAML) and validated;
- ``schema``: the typed models, their checks across fields, the clock's timing rule;
- ``messages``: what a user reads about a bad scenario (validation errors as sentences);
- ``aircraft``: the aircraft's limits read from its JSBSim XML.
"""

from uavxai.errors import ScenarioError
from uavxai.scenario import schema as _schema
from uavxai.scenario.aircraft import (
    aircraft_bank_limit_deg,
    aircraft_height_loop,
    aircraft_roll_rate_deg_s,
    aircraft_speed_range,
    flown_bank_limit_rad,
)
from uavxai.scenario.loader import (
    MAX_DEPTH,
    MAX_FILE_BYTES,
    MAX_NODES,
    MAX_READ_BYTES,
    default_scenario,
    load_scenario,
    parse_scenario,
    read_scenario_text,
    safe_yaml,
)
from uavxai.scenario.messages import (
    REFERENCE,
    checked,
)
from uavxai.scenario.schema import *  # noqa: F403  (every schema name: schema.__all__)

__all__ = [
    "MAX_DEPTH",
    "MAX_FILE_BYTES",
    "MAX_NODES",
    "MAX_READ_BYTES",
    "REFERENCE",
    "ScenarioError",
    "aircraft_bank_limit_deg",
    "aircraft_height_loop",
    "aircraft_roll_rate_deg_s",
    "aircraft_speed_range",
    "flown_bank_limit_rad",
    "checked",
    "default_scenario",
    "load_scenario",
    "parse_scenario",
    "read_scenario_text",
    "safe_yaml",
]
__all__ += _schema.__all__
