"""Each aircraft's ADS-B emitter category (issue 31): the table that says what a planner may
assume of each category, the frames that carry it (real pymavlink bytes), the track that keeps
it and the bank limit its belief hands the planner."""

from __future__ import annotations

import math

import numpy as np
import pytest
from pymavlink.dialects.v20 import common as mavlink

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.errors import UserError
from uavxai.scenario import aircraft_bank_limit_deg, default_scenario, load_scenario
from uavxai.sim.encounter import flight_scenario
from uavxai.surveillance.adsb import (
    Surveillance,
    SurveillanceConfig,
    adsb_message,
    report_from_adsb,
)
from uavxai.surveillance.emitters import (
    EMITTER_TYPES,
    TrafficCategories,
    emitter_category,
    emitter_table,
    emitter_type,
    load_emitter_table,
)
from uavxai.surveillance.imm import ImmTrack
from uavxai.surveillance.tracker import Track, Tracker, truth_beliefs

FRAME = LocalFrame(34.1230, 108.8370, 400.0)
C172 = {"aircraft": "ga_c172", "speed_mps": [40.0, 50.0]}  # the Cessna flies 35-60 m/s


def _traffic(t: float) -> TrafficState:
    """The ownship and two intruders on straight lines 300 m ahead of it (both within the
    onboard sensor's range and field of view)."""
    pos0 = np.array([[0.0, 0.0, 120.0], [-300.0, 300.0, 120.0], [300.0, 300.0, 125.0]])
    vel = np.array([[0.0, 20.0, 0.0], [45.0, 0.0, 0.0], [-45.0, 0.0, 0.0]])
    ids = ("ownship", "intruder-1", "intruder-2")
    airspeed = np.array([20.0, 45.0, 45.0])
    return TrafficState(t=t, ids=ids, pos=pos0 + vel * t, vel=vel, att=np.zeros((3, 3)),
                        airspeed=airspeed)  # fmt: skip


def _heard(categories: TrafficCategories, noncooperative: float = 0.0, track: type = Track):
    """The two intruders heard for 5 s: every ADS-B report packed as MAVLink 2 ADSB_VEHICLE
    bytes, parsed by pymavlink and decoded back, the sensor's detections beside them, all into
    a tracker. Returns (the emitter_type of every frame, the tracker)."""
    cfg = SurveillanceConfig(dropout=0.0, noncooperative=noncooperative)
    surveillance, tracker = Surveillance(cfg, 4, categories), Tracker(track=track)
    sender, receiver = mavlink.MAVLink(None, 1, 1), mavlink.MAVLink(None)
    types = []
    for k in range(51):
        t = k * 0.1
        reports = surveillance.observe(_traffic(t))
        decoded = []
        for r in reports:
            if r.source != "adsb":
                continue
            (msg,) = receiver.parse_buffer(adsb_message(r, FRAME).pack(sender))
            types.append(msg.emitter_type)
            decoded.append(report_from_adsb(msg, FRAME, t_received=t, config=cfg))
        tracker.update([*decoded, *(r for r in reports if r.source == "sensor")])
    return types, tracker


@pytest.mark.parametrize("track", [Track, ImmTrack], ids=["ekf", "imm"])
def test_a_cessna_intruder_broadcasts_light_and_its_track_keeps_it(track):
    categories = TrafficCategories.from_scenario(default_scenario(intruders=C172))
    assert categories.intruders == "LIGHT" and categories.members == "UAV"
    types, tracker = _heard(categories, track=track)
    assert types and set(types) == {mavlink.ADSB_EMITTER_TYPE_LIGHT}  # on the wire
    assert {tr.emitter for tr in tracker.tracks.values()} == {"LIGHT"}
    beliefs = tracker.beliefs(5.0)
    assert len(beliefs) == 2
    # the Cessna's own autopilot limit, read from its XML
    assert {b.bank_limit_deg for b in beliefs} == {aircraft_bank_limit_deg("ga_c172")} == {30.0}


def test_a_uav_intruder_broadcasts_uav_and_a_sensor_track_has_no_category():
    categories = TrafficCategories.from_scenario(default_scenario())  # uav_fw everywhere
    assert categories == TrafficCategories("UAV", "UAV")
    types, tracker = _heard(categories)
    assert set(types) == {mavlink.ADSB_EMITTER_TYPE_UAV}
    assert {b.bank_limit_deg for b in tracker.beliefs(5.0)} == {30.0}
    # non-cooperative: seen by the onboard sensor only, no category, the planner's default
    types, tracker = _heard(categories, noncooperative=1.0)
    assert types == [] and len(tracker.tracks) == 2
    assert {tr.emitter for tr in tracker.tracks.values()} == {None}
    assert {b.bank_limit_deg for b in tracker.beliefs(5.0)} == {None}


def test_an_encounter_campaigns_cessna_is_light_and_truth_knows_it_too():
    """The encounter campaign writes its intruder aircraft (JSBSim's c172x: ga_c172) into the
    scenario it flies; the exact picture gives each intruder its category's limit."""
    flown = flight_scenario(load_scenario("encounters"))
    categories = TrafficCategories.from_scenario(flown)
    assert categories.intruders == "LIGHT"
    beliefs = truth_beliefs(_traffic(0.0), categories)
    assert [b.bank_limit_deg for b in beliefs] == [30.0, 30.0]
    assert [b.bank_limit_deg for b in truth_beliefs(_traffic(0.0))] == [None, None]


def test_the_bridge_publishes_the_intruders_category():
    """`uavxai run`'s truth traffic to ground stations (no surveillance model) carries it too."""
    from uavxai.bridges import telemetry

    sender, receiver = mavlink.MAVLink(None, 1, 1), mavlink.MAVLink(None)
    light = emitter_type("LIGHT")
    messages = telemetry.adsb_vehicles(_traffic(1.0), FRAME, light)
    parsed = [receiver.parse_buffer(m.pack(sender))[0] for m in messages]
    assert len(parsed) == 2 and {m.emitter_type for m in parsed} == {light}


def test_emitter_types_are_mavlinks_and_unknown_values_say_nothing():
    assert emitter_type("UAV") == mavlink.ADSB_EMITTER_TYPE_UAV == 14
    assert emitter_type(None) == mavlink.ADSB_EMITTER_TYPE_NO_INFO
    for name, value in EMITTER_TYPES.items():
        assert emitter_category(value) == name
    assert emitter_category(mavlink.ADSB_EMITTER_TYPE_NO_INFO) is None
    assert emitter_category(200) is None  # not MAVLink's: nothing to assume


def test_the_shipped_table_reads_our_models_limits_from_their_xml():
    table = emitter_table()
    assert table.category("uav_fw") == "UAV" and table.category("ga_c172") == "LIGHT"
    assert table.bank_limit("UAV") == aircraft_bank_limit_deg("uav_fw") == 30.0
    assert table.bank_limit("LIGHT") == aircraft_bank_limit_deg("ga_c172") == 30.0
    for airliner in ("SMALL", "LARGE", "HIGH_VORTEX_LARGE", "HEAVY"):
        assert table.bank_limit(airliner) == 30.0
    assert table.bank_limit("ROTOCRAFT") is None and table.bank_limit(None) is None
    assert table.category("no_such_model") is None


def test_the_xml_bank_limit_is_what_jsbsim_loads():
    """The planner's figure for our models and the autopilot JSBSim flies are one number."""
    from uavxai.dynamics.aircraft import Aircraft

    for name in ("uav_fw", "ga_c172"):
        a = Aircraft(name, FRAME, 1 / 120, seed=1)
        try:
            loaded = math.degrees(a.fdm["ap/bank-limit-rad"])
        finally:
            a.close()
        assert aircraft_bank_limit_deg(name) == pytest.approx(loaded, abs=5e-4)


GOOD = "categories:\n  UAV: {aircraft: uav_fw}\n  LARGE: {bank_limit_deg: 25, source: AIM}\n"


def test_a_table_of_our_own_loads(tmp_path):
    path = tmp_path / "table.yaml"
    path.write_text(GOOD)
    table = load_emitter_table(path)
    assert table.bank_limit("LARGE") == 25.0 and table.bank_limit("UAV") == 30.0
    assert table.category("uav_fw") == "UAV" and table.bank_limit("LIGHT") is None


@pytest.mark.parametrize(
    ("text", "message"),
    [
        ("categories: [UAV]\n", "`categories` must map"),
        ("uav: {aircraft: uav_fw}\n", "the one key `categories`"),
        ("categories:\n  DRONE: {aircraft: uav_fw}\n", r"categories\.DRONE: not a MAVLink .*UAV"),
        ("categories:\n  UAV: {aircraft: f16}\n", r"UAV\.aircraft: 'f16' is not a folder"),
        ("categories:\n  UAV: {aircraft: uav_fw}\n  LIGHT: {aircraft: uav_fw}\n",
         "already categories.UAV's"),
        ("categories:\n  HEAVY: {bank_limit_deg: 95, source: x}\n",
         r"HEAVY\.bank_limit_deg: 95; allowed: .*\(0, 90\)"),
        ("categories:\n  HEAVY: {bank_limit_deg: thirty, source: x}\n", "'thirty'; allowed"),
        ("categories:\n  HEAVY: {bank_limit_deg: .nan, source: x}\n", "nan; allowed"),
        ("categories:\n  HEAVY: {bank_limit_deg: 30, source: ''}\n", "say where the figure"),
        ("categories:\n  HEAVY: {bank_limit_deg: 30}\n", r"allowed: \{aircraft: FOLDER\}"),
        ("categories:\n  HEAVY: {aircraft: uav_fw, bank_limit_deg: 30}\n", "allowed: "),
        ("categories: {UAV: [\n", "not valid YAML at line 2"),
        # a category written twice: the later would silently replace the earlier
        ("categories:\n  LIGHT: {bank_limit_deg: 60, source: x}\n  LIGHT: {aircraft: ga_c172}\n",
         "duplicate key 'LIGHT'"),
    ],
)
def test_a_broken_table_is_refused_by_name(tmp_path, text, message):
    path = tmp_path / "table.yaml"
    path.write_text(text)
    with pytest.raises(UserError, match=message) as err:
        load_emitter_table(path)
    assert str(path) in str(err.value)


def test_a_missing_table_is_a_user_error(tmp_path):
    with pytest.raises(UserError, match="cannot read the emitter table"):
        load_emitter_table(tmp_path / "none.yaml")
