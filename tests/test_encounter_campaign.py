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


# ------------------------------------------------------------- the kinematic height channel
@pytest.mark.parametrize(("h0", "target"), [(100.0, 160.0), (300.0, 280.0), (50.0, 51.0),
                                            (200.0, 20.0)])
def test_height_step_is_the_clipped_first_order_law_integrated_exactly(h0, target) -> None:
    import numpy as np

    from uavxai.sim.kinematic import height_step

    gain, limit, dt = 0.2, 2.5, 1e-4
    h = h0
    for _ in range(int(round(7.0 / dt))):  # Euler at 0.1 ms: the law itself, 7 s of it
        h += dt * min(max(gain * (target - h), -limit), limit)
    exact = float(height_step(np.array([h0]), np.array([target]), gain, limit, 7.0)[0])
    assert exact == pytest.approx(h, abs=1e-3)
    # and in pieces: 7 steps of 1 s land on the same height
    hs = np.array([h0])
    for _ in range(7):
        hs = height_step(hs, np.array([target]), gain, limit, 1.0)
    assert float(hs[0]) == pytest.approx(exact, abs=1e-9)


def test_kinematic_intruders_climb_at_most_at_their_climb_rate_limit() -> None:
    import math
    from types import SimpleNamespace

    import numpy as np

    from uavxai.scenario import default_scenario
    from uavxai.sim.kinematic import KinematicWorld

    # a track climbing at 5 m/s for 30 s: twice what ga_c172's autopilot may climb
    t = np.arange(0.0, 60.01, 0.5)
    vh = np.where((t >= 10) & (t < 40), 5.0, 0.0)
    h = 200.0 + np.concatenate(([0.0], np.cumsum(vh[:-1] * 0.5)))
    track = SimpleNamespace(t=t, x=np.zeros_like(t) + 2000, y=1000 + 45.0 * t, h=h,
                            vx=np.zeros_like(t), vy=np.full_like(t, 45.0), vh=vh)
    sc = default_scenario("climb", seed=1, world={"x": [0, 6000], "y": [0, 6000], "h": [10, 900]},
                          ownship={"start": {"x": 500, "y": 500, "h": 150, "heading_deg": 0,
                                             "speed_mps": 20}},
                          intruders={"aircraft": "ga_c172", "flow": "none", "list": [
                              {"x": 2000, "y": 1000, "h": 200, "heading_deg": 0,
                               "speed_mps": 45}]})
    world = KinematicWorld(sc, tracks={0: track})
    heights, rates = [], []
    for _ in range(90):  # 150 m at 2.5 m/s: a minute's climb, then the track's height
        world.advance(1.0)
        s = world.state()
        heights.append(s.pos[1, 2])
        rates.append(s.vel[1, 2])
    heights, rates = np.array(heights), np.array(rates)
    assert np.max(np.abs(np.diff(heights))) <= 2.5 + 1e-9
    assert np.max(rates) == pytest.approx(2.5)  # it did climb at the limit
    assert heights[-1] == pytest.approx(350.0, abs=1.0)  # and reached the track's height
    assert math.isclose(heights[5], 200.0, abs_tol=1e-6)  # level before the climb


# ------------------------------------------------------------------ encounters flown
def short(duration: int = 60, window: tuple[int, int] = (20, 30), **encounters):
    """The shipped encounter scenario with shorter encounters (test time)."""
    sc = load_scenario(SCENARIO)
    e = sc.encounters.model_copy(update={"duration_s": duration, "tca_window_s": window,
                                         **encounters})
    return sc.model_copy(update={"encounters": e})


def _fly(sc, method: str, seed: int, dynamics: str = "kinematic"):
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.daa_record import DaaObserver
    from uavxai.sim.encounter import fly_encounter, route
    from uavxai.sim.flight_quality import FlightQuality

    start, _ = route(sc)
    quality = FlightQuality((start, sc.ownship.goal))  # the ownship's samples
    keep = DaaObserver(PlannerConfig.from_scenario(sc))  # a second recorder: the intruder
    r, rec, enc = fly_encounter(sc, make_planner(method, PlannerConfig.from_scenario(sc)), seed,
                                dynamics, quality, observers=[keep])
    import numpy as np

    return r, rec, enc, np.array(quality.own), keep.tracks()[:, 0], quality.result()


def test_the_same_encounter_seed_is_the_same_flight() -> None:
    import numpy as np

    sc = short()
    a, b, c = (_fly(sc, "mcts_fast", s) for s in (5, 5, 6))
    assert a[2].weight == b[2].weight and a[2].hmd == b[2].hmd
    assert np.array_equal(a[3], b[3]) and np.array_equal(a[4], b[4])
    assert a[1] == b[1] and a[0].outcome == b[0].outcome
    assert not np.array_equal(a[4], c[4])  # another seed, another intruder


def test_a_flown_encounter_without_avoidance_meets_its_sampled_geometry_at_tca() -> None:
    """Flown with `none` in the kinematic world, the ownship flies its straight route and the
    intruder follows its track (within ~17 m horizontally, ~2.5 m vertically, measured): at the
    TCA their separation is the sampled HMD within 25 m and VMD within 5 m."""
    import math

    import numpy as np

    from uavxai.sim.encounter import route

    sc = short()
    hz = sc.dynamics.trajectory_hz
    checked = 0
    for seed in range(8):
        r, rec, enc, own, intr, quality = _fly(sc, "none", seed)
        start, heading = route(sc)
        ahead = np.array([math.sin(heading), math.cos(heading)])
        across = own[:, :2] - start[:2] - np.outer((own[:, :2] - start[:2]) @ ahead, ahead)
        assert np.abs(across).max() < 1e-6 and np.abs(own[:, 2] - start[2]).max() < 1e-6
        k = int(round(enc.tca * hz))
        floor = sc.encounters.intruder_floor_m
        if k >= len(own) or enc.intruder.h[int(enc.tca)] <= floor:
            continue  # ended by a collision before TCA, or held up by the floor there
        checked += 1
        assert math.hypot(*(intr[k, :2] - own[k, :2])) == pytest.approx(enc.hmd, abs=25.0)
        assert intr[k, 2] - own[k, 2] == pytest.approx(enc.vmd, abs=5.0)
        assert rec.hmd_m <= enc.hmd + 25.0  # the flown closest approach is no farther
        assert quality.path_excess == pytest.approx(0.0, abs=1e-9)
        assert not rec.alert and not rec.manoeuvre and rec.reversals == 0
    assert checked >= 5


# --------------------------------------------------------------------------- campaigns
def test_a_small_kinematic_encounter_campaign_writes_the_daa_columns(tmp_path) -> None:
    import csv
    import math

    from uavxai.campaign import DAA_COLUMNS, DAA_EPISODE_COLUMNS, evaluate_command
    from uavxai.errors import UserError
    from uavxai.sim.encounter import draw_encounter

    sc = short(duration=40, window=(15, 25))
    out = tmp_path / "campaign"
    evaluate_command(sc, ["none", "mcts_fast"], [1], 6, "kinematic", 1, None, out)
    with (out / "episodes.csv").open() as f:
        episodes = list(csv.DictReader(f))
    with (out / "results.csv").open() as f:
        results = {r["method"]: r for r in csv.DictReader(f)}
    assert len(episodes) == 12 and set(DAA_EPISODE_COLUMNS) <= set(episodes[0])
    for r in episodes:
        seed = int(r["seed"])
        assert seed == sc.seed + int(r["episode"]) and r["intruders"] == "1"
        # the weight is the encounter's, drawn again alone from its seed
        assert float(r["weight"]) == pytest.approx(draw_encounter(sc, seed).weight, rel=1e-5)
        assert math.isfinite(float(r["hmd_m"])) and math.isfinite(float(r["vmd_m"]))
        assert float(r["vmd_m"]) >= 0 and int(r["reversals"]) >= 0
        assert r["lowc"] in "01" and r["alert"] in "01" and r["manoeuvre"] in "01"
        if r["outcome"] != "collision":
            assert float(r["path_excess"]) >= -1e-9
        if r["method"] == "none":
            assert (r["alert"], r["manoeuvre"], r["reversals"]) == ("0", "0", "0")
            assert float(r["path_excess"]) == pytest.approx(0.0, abs=1e-6)
        # an NMAC is inside the well-clear cylinder too
        assert not (r["nmac"] == "1" and r["lowc"] == "0")
    assert set(results) == {"none", "mcts_fast"} and set(DAA_COLUMNS) <= set(results["none"])
    for method, r in results.items():
        for k in ("nmac_prob", "lowc_prob", "alert_rate", "mean_reversals", "mean_path_excess"):
            assert math.isfinite(float(r[k])), (method, k)
        assert 0.0 <= float(r["nmac_prob_lo"]) <= float(r["nmac_prob"]) <= float(r["nmac_prob_hi"])
        assert r["ci_check"] in ("ok", "wide")
    none = results["none"]
    if float(none["lowc_prob"]) > 0:  # the baseline against itself: ratio 1
        assert float(none["lowc_ratio"]) == pytest.approx(1.0)
    assert float(none["alert_rate"]) == 0.0
    # the weighted probabilities are the weighted means of the episode columns
    for method, r in results.items():
        rows = [e for e in episodes if e["method"] == method]
        w = [float(e["weight"]) for e in rows]
        lowc = sum(wi for wi, e in zip(w, rows, strict=True) if e["lowc"] == "1") / sum(w)
        assert float(r["lowc_prob"]) == pytest.approx(lowc, rel=1e-5)
    # merge: the same campaign split in two by seed pools back into the same results
    from uavxai.campaign import merge_campaigns

    halves = (("a", lambda e: int(e["episode"]) < 3), ("b", lambda e: int(e["episode"]) >= 3))
    for part, keep in halves:
        folder = tmp_path / part
        folder.mkdir()
        with (folder / "episodes.csv").open("w", newline="") as f:
            w = csv.DictWriter(f, list(episodes[0]))
            w.writeheader()
            w.writerows(e for e in episodes if keep(e))
        (folder / "results.csv").write_text((out / "results.csv").read_text())
    merged = {r["method"]: r for r in merge_campaigns([tmp_path / "a", tmp_path / "b"],
                                                       tmp_path / "m")}
    for method, r in results.items():
        for k in ("nmac_prob", "lowc_prob", "lowc_prob_hi", "alert_rate", "mean_path_excess"):
            assert float(merged[method][k]) == pytest.approx(float(r[k]), rel=1e-4), k
    with (tmp_path / "a" / "episodes.csv").open() as f:
        broken = f.read().replace(f",{episodes[0]['weight']},", ",-1,", 1)
    (tmp_path / "a" / "episodes.csv").write_text(broken)
    with pytest.raises(UserError, match="weight"):
        merge_campaigns([tmp_path / "a", tmp_path / "b"], tmp_path / "m2")


def test_intruder_counts_are_refused_for_an_encounter_scenario(tmp_path) -> None:
    from uavxai.campaign import run_campaign
    from uavxai.cli import main
    from uavxai.errors import UserError

    with pytest.raises(UserError, match="leave --intruders out"):
        run_campaign(short(), ["none"], [5], 1)
    code = main(["evaluate", str(SCENARIO), "--methods", "none", "--intruders", "5",
                 "--episodes", "1", "--out", str(tmp_path / "x")])
    assert code != 0 and not (tmp_path / "x").exists()


def test_a_jsbsim_encounter_with_a_cessna_flies_to_its_end_and_records_its_columns() -> None:
    """Encounter 2 (an NMAC-class one: HMD 85 m, VMD 24 m at TCA 13 s) in JSBSim, the
    intruder a ga_c172: flown out (30 s) with `none` it passes near its sampled geometry (the
    Cessna follows its track within ~10 m); flown with mcts_vertical, the row has every
    column."""
    import math

    from uavxai.campaign import DAA_EPISODE_COLUMNS, run_campaign_episode
    from uavxai.sim.encounter import draw_encounter

    sc = short(duration=30, window=(10, 20))
    enc = draw_encounter(sc, 2)
    r, rec, _, own, intr, _ = _fly(sc, "none", 2, "jsbsim")
    assert r.outcome.value == "timeout" and r.steps == 30  # flown to its end, no failure
    assert rec.weight == enc.weight and rec.lowc  # 85 m by 24 m: inside well clear
    assert rec.hmd_m == pytest.approx(enc.hmd, abs=30.0)
    assert rec.vmd_m == pytest.approx(abs(enc.vmd), abs=10.0)
    assert len(own) == len(intr) == 30 * sc.dynamics.trajectory_hz + 1
    row = run_campaign_episode(sc, "mcts_vertical", 1, 2, "jsbsim")
    assert row["outcome"] in ("timeout", "collision")
    assert row["weight"] == pytest.approx(enc.weight)
    for k in DAA_EPISODE_COLUMNS:
        assert math.isfinite(float(row[k])), k
    assert row["manoeuvre"] == 1 and row["alert"] == 1  # an NMAC ahead: it does something


def test_a_track_limited_to_the_top_speed_flies_in_jsbsim() -> None:
    """Encounter 216's Cessna is limited to its top speed, 60 m/s, and hypot(vx, vy) of the
    limited track rounds to 60.00000000000001: the world took that for a speed out of the
    aircraft's range and stopped the JSBSim campaign there. A rounding is inside the range;
    a real excess is still refused."""
    from uavxai.dynamics.world import JSBSimWorld
    from uavxai.errors import UserError
    from uavxai.sim.encounter import draw_encounter, intruder_spec

    sc = load_scenario(scenarios_dir() / "encounters.yaml")
    assert intruder_spec(draw_encounter(sc, 216)).speed_mps > 60.0  # the case, as sampled
    r, *_ = _fly(sc, "none", 216, "jsbsim")
    assert r.outcome.value in ("timeout", "collision") and r.steps > 0
    with pytest.raises(UserError, match="flies between 35 and 60 m/s"):
        JSBSimWorld._check_speed("intruder 1 speed_mps", 60.01, "ga_c172", (35.0, 60.0))


# ------------------------------------------------------------ the intruder aircraft's limits
def test_limit_track_bounds_speed_vertical_rate_and_turn_rate_and_keeps_flyable_tracks() -> None:
    import math

    import numpy as np

    from uavxai.encounters import default_model, sample_track
    from uavxai.encounters.tracks import limit_track

    model, rng = default_model(), np.random.default_rng(4)
    bank, g = math.radians(24.0), 9.80665
    changed = 0
    for _ in range(20):
        tr = sample_track(model, rng, 120, {"G": 0, "A": 3, "L": 0})
        lim = limit_track(tr, max_speed=60.0, max_vertical_rate=2.5, max_bank=bank)
        speed = lim.speed
        assert speed.max() <= 60.0 + 1e-9 and np.abs(lim.vh).max() <= 2.5 + 1e-12
        rate = np.abs(np.diff(np.unwrap(np.arctan2(lim.vx, lim.vy))))  # per 1-s step
        assert np.all(rate <= g * math.tan(bank) / speed[:-1] + 1e-9)
        # positions are the integral of the velocities (sample2track's Euler step)
        assert np.allclose(np.diff(lim.x), lim.vx[:-1]) and np.allclose(np.diff(lim.h), lim.vh[:-1])
        if lim is tr:  # nothing beyond the limits: the very same track
            assert tr.speed.max() <= 60 and np.abs(tr.vh).max() <= 2.5
        else:
            changed += 1
    assert changed > 0
    unlimited = sample_track(model, np.random.default_rng(5), 120, {"G": 0, "A": 3, "L": 0})
    assert limit_track(unlimited) is unlimited
