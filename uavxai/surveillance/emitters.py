"""What a planner may assume of an aircraft it tracks, by its ADS-B emitter category (issue 31).

ADS-B says what kind of aircraft sends it: DO-260B's emitter category, MAVLink's
``ADSB_EMITTER_TYPE`` field of ADSB_VEHICLE. The table ``aircraft/emitter_categories.yaml``
gives, per category, the envelope a planner may assume of such traffic: one of our aircraft
models (whose autopilot XML then gives the bank limit it declares, one source; the worlds fly
``avoidance.bank_limit_deg``, docs/scenario.md) or a
figure with its source, for traffic we have no model of (real ADS-B, a BlueSky bridge's
airliners). The same table says which category each of our models broadcasts. A category the
table leaves out, and a track with none (the onboard sensor's), get the planner's default,
``avoidance.mcts.intruder_bank_limit_deg``.

Only the bank limit is used: it bounds the turns an intruder could start, the reachable-set
margin of the tree planners (:func:`uavxai.avoidance.model.intruder_margin`); docs/scenario.md
("surveillance") says which other figures could be.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

from uavxai.dynamics.state import is_member
from uavxai.errors import UserError
from uavxai.paths import aircraft_dir
from uavxai.scenario import Scenario, aircraft_bank_limit_deg
from uavxai.scenario.loader import safe_yaml

TABLE_NAME = "emitter_categories.yaml"
_PREFIX = "ADSB_EMITTER_TYPE_"
# MAVLink's emitter categories by name less the prefix (LIGHT, UAV, ...), NO_INFO and the
# enum's end left out: they say nothing about an aircraft
EMITTER_TYPES: dict[str, int] = {
    e.name.removeprefix(_PREFIX): value
    for value, e in mavlink.enums["ADSB_EMITTER_TYPE"].items()
    if e.name not in (f"{_PREFIX}NO_INFO", f"{_PREFIX}ENUM_END")
}
_CATEGORY_OF = {value: name for name, value in EMITTER_TYPES.items()}


def emitter_type(category: str | None) -> int:
    """The ADSB_VEHICLE ``emitter_type`` of ``category`` (None: NO_INFO)."""
    return mavlink.ADSB_EMITTER_TYPE_NO_INFO if category is None else EMITTER_TYPES[category]


def emitter_category(value: int) -> str | None:
    """The category an ADSB_VEHICLE ``emitter_type`` names; None for NO_INFO or a value
    MAVLink does not define (a frame from elsewhere says nothing we can use)."""
    return _CATEGORY_OF.get(int(value))


@dataclass(frozen=True)
class EmitterTable:
    """The table of ``aircraft/emitter_categories.yaml``: the bank limit (deg) a planner may
    assume per category, and the category each of our aircraft models broadcasts."""

    bank_limit_deg: dict[str, float]
    category_of_aircraft: dict[str, str]

    def bank_limit(self, category: str | None) -> float | None:
        """The bank limit (deg) of ``category``; None: the table has none (the planner's
        default applies)."""
        return None if category is None else self.bank_limit_deg.get(category)

    def category(self, aircraft: str) -> str | None:
        """The category the aircraft model ``aircraft`` broadcasts; None (NO_INFO) for a
        model the table does not name."""
        return self.category_of_aircraft.get(aircraft)


def load_emitter_table(path: str | Path) -> EmitterTable:
    """Read and check an emitter table (the module docstring; the shipped one's comments say
    the format); a :class:`UserError` naming the file, the entry and what is allowed."""
    p = Path(path)
    try:
        text = p.read_text(encoding="utf-8")
    except (OSError, UnicodeDecodeError) as exc:
        raise UserError(f"{p}: cannot read the emitter table ({exc}).") from None
    # the scenario files' reader: bounded, and a key written twice is refused, not silently
    # replaced (a user raising LIGHT's limit above would otherwise lose it to a later LIGHT)
    data = safe_yaml(text, str(p))
    if not isinstance(data, dict) or set(data) != {"categories"}:
        raise UserError(f"{p}: the emitter table must be a mapping with the one key `categories`.")
    entries = data["categories"]
    if not isinstance(entries, dict) or not entries:
        raise UserError(f"{p}: `categories` must map emitter categories to their entries.")
    limits: dict[str, float] = {}
    aircraft: dict[str, str] = {}
    for name, entry in entries.items():
        where = f"{p}: categories.{name}"
        if name not in EMITTER_TYPES:
            raise UserError(f"{where}: not a MAVLink emitter category; allowed: "
                            f"{', '.join(EMITTER_TYPES)}.")  # fmt: skip
        limits[name] = _entry_limit(where, entry)
        model = entry.get("aircraft")
        if model in aircraft:
            raise UserError(f"{where}: aircraft {model!r} is already categories."
                            f"{aircraft[model]}'s; one category an aircraft.")  # fmt: skip
        if model is not None:
            aircraft[model] = name
    return EmitterTable(limits, aircraft)


def _entry_limit(where: str, entry: Any) -> float:
    """The bank limit (deg) of one category's entry: its aircraft model's or its figure."""
    if isinstance(entry, dict) and set(entry) == {"aircraft"}:
        model = entry["aircraft"]
        if not isinstance(model, str) or not (aircraft_dir() / model / f"{model}.xml").is_file():
            raise UserError(f"{where}.aircraft: {model!r} is not a folder under aircraft/.")
        limit = aircraft_bank_limit_deg(model)
        if limit is None:
            raise UserError(f"{where}.aircraft: {model}'s autopilot declares no ap/bank-limit-rad.")
        return limit
    if isinstance(entry, dict) and set(entry) == {"bank_limit_deg", "source"}:
        limit, source = entry["bank_limit_deg"], entry["source"]
        number = isinstance(limit, int | float) and not isinstance(limit, bool)
        if not (number and math.isfinite(limit) and 0 < limit < 90):
            raise UserError(f"{where}.bank_limit_deg: {limit!r}; allowed: a number of degrees "
                            "in (0, 90).")  # fmt: skip
        if not isinstance(source, str) or not source.strip():
            raise UserError(f"{where}.source: say where the figure comes from (a non-empty text).")
        return float(limit)
    raise UserError(f"{where}: {entry!r}; allowed: {{aircraft: FOLDER}} (one of our models) or "
                    "{bank_limit_deg: N, source: TEXT}.")  # fmt: skip


@cache
def emitter_table() -> EmitterTable:
    """The shipped table, ``aircraft/emitter_categories.yaml``."""
    return load_emitter_table(aircraft_dir() / TABLE_NAME)


@dataclass(frozen=True)
class TrafficCategories:
    """The category each aircraft of an episode broadcasts: the intruders fly the scenario's
    ``intruders.aircraft`` (an encounter campaign's, ``encounters.intruder_aircraft``, is
    written there), a fleet's members its ``ownship.aircraft``. The default is what
    surveillance sent before issue 31: every aircraft a UAV."""

    intruders: str | None = "UAV"
    members: str | None = "UAV"

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> TrafficCategories:
        table = emitter_table()
        return cls(table.category(scenario.intruders.aircraft),
                   table.category(scenario.ownship.aircraft))  # fmt: skip

    def of(self, ident: str) -> str | None:
        """The category aircraft ``ident`` broadcasts (None: NO_INFO)."""
        return self.members if is_member(ident) else self.intruders

    def bank_limit_deg(self, ident: str) -> float | None:
        """The bank limit (deg) a planner may assume of aircraft ``ident`` (None: the
        planner's default)."""
        return emitter_table().bank_limit(self.of(ident))
