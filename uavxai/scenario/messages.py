"""What a user reads about a bad scenario: values shown short and printable, a validation
error as a sentence (an unknown key with the nearest valid one), the reference to read.
"""

from __future__ import annotations

import difflib
from collections.abc import Callable
from typing import Any, TypeVar

from pydantic import BaseModel, ValidationError

from uavxai.errors import UserError, short_repr

REFERENCE = "docs/scenario.md"
M = TypeVar("M", bound=BaseModel)


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


def short_value(value: Any) -> str:
    """A bounded repr (:func:`uavxai.errors.short_repr`); a mapping is named, not shown."""
    if isinstance(value, dict):
        return "a mapping"
    shown = short_repr(value)
    return shown if len(shown) <= 80 else shown[:77] + "..."


def printable(text: str, limit: int = 120) -> str:
    """``text`` with control characters escaped (no raw ANSI escapes reach the terminal),
    cut to ``limit`` characters."""
    text = text[: limit * 4]
    clean = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return clean if len(clean) <= limit else clean[: limit - 3] + "..."


def describe(err: dict[str, Any], model: type[BaseModel]) -> str:
    """One validation error of ``model`` as a sentence naming the key, the value and the rule
    (an unknown key: the nearest valid one and every allowed key there)."""
    loc = printable(".".join(str(p) for p in err["loc"]))
    kind = err["type"]
    value = err.get("input")
    if kind == "extra_forbidden":
        key = str(err["loc"][-1])
        allowed = _allowed_keys(model, err["loc"])
        near = difflib.get_close_matches(key[:100], allowed, n=1, cutoff=0.5)
        hint = f" Did you mean '{near[0]}'?" if near else ""
        return f"'{loc}': unknown key.{hint} Allowed here: {', '.join(allowed)}."
    if kind == "missing":
        return f"'{loc}': required but missing."
    if kind in ("model_type", "dict_type"):
        keys = _allowed_keys(model, (*err["loc"], "_"))  # the section's own keys
        if keys:
            return (f"'{loc}' = {short_value(value)}: a section belongs here, a mapping of "
                    f"{', '.join(keys)} (e.g. {{{keys[0]}: ...}}).")  # fmt: skip
    msg = printable(err["msg"].removeprefix("Value error, "), 400)
    if not loc:
        return f"{msg}."
    return f"'{loc}' = {short_value(value)}: {msg}."


def invalid_scenario(source: str, errors: list[Any], model: type[BaseModel]) -> str:
    """The message of a scenario that ``model`` refused with ``errors`` (pydantic's): the
    first ten as sentences, whether the checks across fields are still to run, the
    reference."""
    lines = [describe(e, model) for e in errors[:10]]
    if len(errors) > 10:
        lines.append(f"... and {len(errors) - 10} more")
    n = len(errors)
    cross = [e for e in errors if e.get("type") == "value_error" and not e.get("loc")]
    later = (
        "" if cross or n == 0 else
        "\nThe checks across fields (world bounds, airspeeds, timing, wind, orbit, sensors) "
        "run once these are fixed and may find more."
    )  # fmt: skip
    return (
        f"{source}: invalid scenario ({n} problem{'s' if n > 1 else ''}):\n  "
        + "\n  ".join(lines)
        + later
        + f"\nSee the scenario reference {REFERENCE} (units: m, s; *_deg in degrees)."
    )


def checked(model: type[M], data: dict[str, Any], owner: str,
            name_of: Callable[[tuple[Any, ...]], str] | None = None) -> M:  # fmt: skip
    """``data`` validated by the schema's ``model`` (its bounds, its validators: the one check
    of those settings) for a config built in code rather than read from a scenario (a
    :class:`uavxai.avoidance.types.PlannerConfig`, say). A problem is a :class:`UserError`
    naming ``owner.field`` (``name_of`` turns a validation error's location into the owner's
    field name; by default the dotted location) and what is allowed."""
    try:
        return model.model_validate(data)
    except ValidationError as exc:
        problems = []
        for err in exc.errors():
            name = name_of(err["loc"]) if name_of else ".".join(str(p) for p in err["loc"])
            if name:
                problems.append(describe({**err, "loc": (f"{owner}.{name}",)}, model))
            else:  # a check across fields: its message names them
                problems.append(f"{owner}: {describe({**err, 'loc': ()}, model)}")
        raise UserError(" ".join(problems)) from None
