"""What every section of the scenario schema shares: the base model (unknown keys refused,
frozen, no value coerced from another type), the bounded number types, names that become
folder names, ordered pairs and checkpoint files."""

from __future__ import annotations

import functools
import re
import typing
from pathlib import Path
from typing import Annotated, Any, Literal

from pydantic import BaseModel, ConfigDict, Field, ValidationInfo, field_validator

from uavxai.scenario.messages import printable, short_value

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


def ordered_pair(value: tuple[float, float], what: str) -> tuple[float, float]:
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


@functools.cache
def _scalar_rules(model: type[BaseModel], name: str) -> tuple[bool, bool, bool, bool]:
    """(admits text, admits a boolean, is a boolean, holds sections) of the type of ``model``'s
    field ``name``: what :func:`_strict_scalars` asks of it, worked out once per field (a
    planner's config is validated by these models whenever it is built)."""
    ann = model.model_fields[name].annotation
    return _admits(ann, str), _admits(ann, bool), ann is bool, _holds_sections(ann)


def _strict_scalars(value: Any, rules: tuple[bool, bool, bool, bool]) -> None:
    """Refuse what pydantic's lax mode would coerce: text for a number or a boolean ('9' -> 9,
    'yes' -> true) and booleans or numbers for one another (true -> 1, 1 -> true)."""
    admits_str, admits_bool, is_bool, holds_sections = rules
    if isinstance(value, dict):
        return  # a nested section: its own model checks its fields
    if isinstance(value, list | tuple):
        if holds_sections:
            return  # a list of sections: each item's model checks it, and says what it is
        for item in value:
            _strict_scalars(item, rules)
        return
    if isinstance(value, str) and not admits_str:
        raise ValueError(
            "text where a number or true/false belongs; write it without quotes (text is never "
            "converted)"
        )
    if isinstance(value, bool) and not admits_bool:
        raise ValueError("a boolean where a number belongs")
    if isinstance(value, int | float) and not isinstance(value, bool) and is_bool:
        raise ValueError("a number where true or false belongs")


class Section(BaseModel):
    """A section of the scenario: unknown keys refused, frozen, every default validated, no
    value coerced from another type."""

    model_config = ConfigDict(extra="forbid", frozen=True, validate_default=True)

    @field_validator("*", mode="before")
    @classmethod
    def _no_coercion(cls, value: Any, info: ValidationInfo) -> Any:
        _strict_scalars(value, _scalar_rules(cls, info.field_name))
        return value


def checkpoint_exists(value: str | None, what: str) -> str | None:
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


AircraftName = Annotated[str, Field(min_length=1, max_length=100)]
