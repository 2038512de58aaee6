"""The aircraft's limits as its JSBSim XML declares them (airspeeds, the height loop, the roll
rate), read without starting JSBSim so that validating a scenario stays cheap: the schema
checks speeds against them and the planners' models fly by them.
"""

from __future__ import annotations

import contextlib
import math
import xml.etree.ElementTree as ET
from functools import cache

from uavxai.paths import aircraft_dir


@cache
def _autopilot(name: str) -> tuple[dict[str, float], dict[str, float]]:
    """The aircraft's autopilot as its XML declares it, read without starting JSBSim (so that
    validation stays cheap): the initial values of its ``<property value=...>`` and the gains
    of its ``<pure_gain>`` components, by name."""
    values: dict[str, float] = {}
    gains: dict[str, float] = {}
    for xml in sorted((aircraft_dir() / name).rglob("*.xml")):
        try:
            root = ET.parse(xml).getroot()
        except (ET.ParseError, OSError):
            continue
        for prop in root.iter("property"):
            if "value" in prop.attrib:
                values[(prop.text or "").strip()] = float(prop.attrib["value"])
        for el in root.iter("pure_gain"):
            gain = el.find("gain")
            text = "" if gain is None else (gain.text or "").strip()
            with contextlib.suppress(ValueError):  # a gain may be a property: not a constant
                gains[el.get("name", "")] = float(text)
    return values, gains


def aircraft_speed_range(name: str) -> tuple[float, float]:
    """The airspeeds (m/s) the aircraft's autopilot accepts: the initial values of
    ``ap/speed-min-mps`` and ``ap/speed-max-mps`` in its XML, which JSBSim loads and
    :attr:`uavxai.dynamics.aircraft.Aircraft.speed_range` reads back (a test checks both
    agree). An aircraft without them: no limit known beyond the schema."""
    values, _ = _autopilot(name)
    if "ap/speed-min-mps" not in values or "ap/speed-max-mps" not in values:
        return 0.0, math.inf
    return values["ap/speed-min-mps"], values["ap/speed-max-mps"]


def aircraft_height_loop(name: str) -> tuple[float, float]:
    """(gain 1/s, climb-rate limit m/s) of the aircraft autopilot's height loop: the climb-rate
    demand is gain x (height target - height), clipped to +-limit (the gain of its
    ``ap/climb-rate-cmd-mps`` and the initial value of ``ap/climb-rate-limit-mps`` in its XML).
    An aircraft without them: (0.2, 2.5), the values of ours."""
    values, gains = _autopilot(name)
    return gains.get("ap/climb-rate-cmd-mps", 0.2), values.get("ap/climb-rate-limit-mps", 2.5)


def aircraft_roll_rate_deg_s(name: str) -> float:
    """The roll-rate limit (deg/s) of the aircraft's autopilot, ``ap/roll-rate-limit-rad_sec``
    in its XML, to a thousandth of a degree (the XML writes 30 deg/s as 0.5236 rad/s). An
    aircraft without it: 30, the value of ours."""
    values, _ = _autopilot(name)
    rate = values.get("ap/roll-rate-limit-rad_sec")
    return 30.0 if rate is None else round(math.degrees(rate), 3)


def aircraft_bank_limit_deg(name: str) -> float | None:
    """The bank limit (deg) of the aircraft's autopilot, ``ap/bank-limit-rad`` in its XML, to
    a thousandth of a degree (the XML writes 30 deg as 0.5236 rad); None if it declares none."""
    values, _ = _autopilot(name)
    limit = values.get("ap/bank-limit-rad")
    return None if limit is None else round(math.degrees(limit), 3)


def flown_bank_limit_rad(name: str, fallback_deg: float) -> float:
    """The bank limit (rad) an aircraft of model ``name`` is flown within: its autopilot's
    (:func:`aircraft_bank_limit_deg`), or ``fallback_deg`` (the scenario's
    ``avoidance.bank_limit_deg``) if its XML declares none. Intruders fly their own limit,
    not the ownship's setting, so the turn cover the planner gives a track (its emitter
    category's limit) matches how the intruder turns."""
    limit = aircraft_bank_limit_deg(name)
    return math.radians(fallback_deg if limit is None else limit)
