"""The planner settings a scenario declares, derived from its schema: each is declared once, in
uavxai/scenario/schema (its type, default, bounds and validators), and reaches
:class:`uavxai.avoidance.types.PlannerConfig` from there with no other edit.

The rule (docs/architecture.md, "Adding a planner setting"): every key of the scenario's
`avoidance` section and of its sub-sections (`avoidance.mcts`) is a PlannerConfig field of the
same name, but those in :data:`ENGINE_KEYS`; the world's bounds and the two cylinders
(`nmac`, `well_clear`) the planner reads under names of their own (:data:`WORLD_BOUNDS`,
:data:`CYLINDERS`). :data:`SchemaSettings` is the dataclass of those fields with the schema's
defaults; PlannerConfig adds the planner-only settings to it and validates the schema's with the
schema's own models (:func:`check_schema_settings`).
"""

from __future__ import annotations

import dataclasses
from typing import Any

from pydantic import BaseModel

from uavxai.scenario import Avoidance, World, checked

# The `avoidance` keys that are not settings of the search: which planner flies and the file of
# its weights (uavxai.avoidance.planners reads them), and when its command reaches the
# autopilot (the engine's: uavxai.sim.companion).
ENGINE_KEYS = ("planner", "checkpoint", "decision_latency_s")
# The schema's settings the planner reads under names of its own: the flight area's bounds (the
# world's x, y, h), and the well-clear and NMAC cylinders as (horizontal, vertical) m.
WORLD_BOUNDS = {"x_bounds": "x", "y_bounds": "y", "h_bounds": "h"}
CYLINDERS = {"alert_well_clear_m": "well_clear", "nmac_m": "nmac"}
_PAIR = ("horizontal_m", "vertical_m")
_SECTIONS = {"world": World, "avoidance": Avoidance}


def _section(annotation: Any) -> type[BaseModel] | None:
    is_model = isinstance(annotation, type) and issubclass(annotation, BaseModel)
    return annotation if is_model else None


def _paths() -> dict[str, tuple[str, ...]]:
    """Each schema-declared PlannerConfig field -> where a scenario holds it (section, key, ...)."""
    paths = {name: ("world", key) for name, key in WORLD_BOUNDS.items()}
    pairs = {key: name for name, key in CYLINDERS.items()}
    for key, info in Avoidance.model_fields.items():
        sub = _section(info.annotation)
        if key in ENGINE_KEYS:
            continue
        if key in pairs:
            paths[pairs[key]] = ("avoidance", key)
        elif sub is not None:  # a sub-section (mcts): its keys under their own names
            for inner in sub.model_fields:
                if inner in paths:
                    raise TypeError(f"avoidance.{key}.{inner} repeats a planner setting's name")
                paths[inner] = ("avoidance", key, inner)
        else:
            paths[key] = ("avoidance", key)
    return paths


SCHEMA_PATHS = _paths()


def schema_settings(avoidance: Avoidance, world: World) -> dict[str, Any]:
    """The planner settings of a scenario's `avoidance` section and world, by PlannerConfig
    field (:data:`SCHEMA_PATHS`)."""
    sections = {"world": world, "avoidance": avoidance}
    out: dict[str, Any] = {}
    for name, (section, *keys) in SCHEMA_PATHS.items():
        value: Any = sections[section]
        for key in keys:
            value = getattr(value, key)
        out[name] = tuple(getattr(value, k) for k in _PAIR) if name in CYLINDERS else value
    return out


def _nested(values: dict[str, Any]) -> dict[str, dict[str, Any]]:
    """PlannerConfig's schema settings ``values`` as the scenario's sections would hold them
    (the inverse of :func:`schema_settings`)."""
    data: dict[str, dict[str, Any]] = {"world": {}, "avoidance": {}}
    for name, (section, *keys) in SCHEMA_PATHS.items():
        value = values[name]
        if name in CYLINDERS and isinstance(value, tuple | list) and len(value) == 2:
            value = dict(zip(_PAIR, value, strict=True))
        node = data[section]
        for key in keys[:-1]:
            node = node.setdefault(key, {})
        node[keys[-1]] = value
    return data


def _field_at(section: str, loc: tuple[Any, ...]) -> str:
    """The PlannerConfig field a validation error's location points into ("": none, a check
    across fields)."""
    where = (section, *loc)
    for name, path in SCHEMA_PATHS.items():
        if where[: len(path)] == path:
            return name
    return ""


def check_schema_settings(values: dict[str, Any], owner: str) -> dict[str, Any]:
    """``values`` (PlannerConfig's schema settings) validated by the schema's own models, as
    the scenario's sections would hold them; the values as the schema keeps them (tuples,
    floats). A problem is a :class:`UserError` naming ``owner.field``."""
    data = _nested(values)
    models = {
        section: checked(model, data[section], owner, lambda loc, s=section: _field_at(s, loc))
        for section, model in _SECTIONS.items()
    }
    return schema_settings(models["avoidance"], models["world"])


def _annotation(section: str, keys: list[str], name: str) -> Any:
    if name in CYLINDERS:
        return tuple[float, float]
    model: Any = _SECTIONS[section]
    for key in keys[:-1]:
        model = _section(model.model_fields[key].annotation)
    return model.model_fields[keys[-1]].annotation


# The dataclass of the schema-declared settings with the schema's defaults: PlannerConfig's
# base, so that those fields are written nowhere but in the schema.
SchemaSettings = dataclasses.make_dataclass(
    "SchemaSettings",
    [
        (name, _annotation(section, keys, name), dataclasses.field(default=default))
        for (name, (section, *keys)), default in zip(
            SCHEMA_PATHS.items(), schema_settings(Avoidance(), World()).values(), strict=True
        )
    ],
    frozen=True,
)
SchemaSettings.__module__ = __name__  # make_dataclass's keyword for it is Python 3.12's
