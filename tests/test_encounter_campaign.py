"""Encounter campaigns (issue 27): the `encounters` scenario section, encounters flown in the
kinematic world and in JSBSim, and their detect-and-avoid columns."""

from __future__ import annotations

import copy

import pytest
import yaml

from uavxai.errors import ScenarioError
from uavxai.paths import scenarios_dir
from uavxai.scenario import load_scenario, parse_scenario

SCENARIO = scenarios_dir() / "encounters.yaml"


def _data() -> dict:
    return yaml.safe_load(SCENARIO.read_text(encoding="utf-8"))


# ------------------------------------------------------------------------------ the schema
def test_encounter_scenario_loads_with_the_spec_keys_and_defaults() -> None:
    sc = load_scenario(SCENARIO)
    e = sc.encounters
    assert (e.model, e.parameters, e.importance, e.duration_s) == ("mitll_uncor", None, "nmac", 120)
    assert e.intruder_aircraft == "c172x" and e.aircraft == "ga_c172"
    assert (sc.avoidance.well_clear.horizontal_m, sc.avoidance.well_clear.vertical_m) == (
        pytest.approx(609.6), pytest.approx(76.2))
    data = _data()
    data["encounters"] = {}  # every key has a default
    d = parse_scenario(data).encounters
    assert (d.aircraft, d.importance, d.tca_window_s, d.hmd_max_m) == ("ga_c172", "nmac",
                                                                       (45, 75), 1852.0)
    data.pop("encounters")
    assert parse_scenario(data).encounters is None


@pytest.mark.parametrize(
    ("change", "message"),
    [
        ({"encounters": {"model": "mitll_cor"}}, "encounters.model"),
        ({"encounters": {"importance": "lowc"}}, "encounters.importance"),
        ({"encounters": {"intruder_aircraft": "b747"}}, "not a folder under aircraft"),
        ({"encounters": {"duration_s": 60, "tca_window_s": [45, 75]}}, "tca_window_s"),
        ({"encounters": {"tca_window_s": [75, 45]}}, "tca_window_s"),
        ({"encounters": {"hmd_max_m": 100}}, "hmd_max_m"),
        ({"encounters": {"parameters": "/no/such/file.txt"}}, "no such file"),
        ({"encounters": {"duration_s": 1.5}}, "duration_s"),
        ({"encounters": {"typo": 1}}, "typo"),
        ({"intruders": {"flow": "replace"}}, "intruders.flow: none"),
        ({"ownship": {"goal": None}}, "ownship.goal"),
        ({"avoidance": {"well_clear": {"horizontal_m": -1}}}, "well_clear"),
    ],
)
def test_invalid_encounter_sections_are_refused_with_the_key(change, message) -> None:
    data = copy.deepcopy(_data())
    for section, values in change.items():
        data.setdefault(section, {}).update(values)
    with pytest.raises(ScenarioError, match=message):
        parse_scenario(data)
