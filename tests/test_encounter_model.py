"""The MIT LL encounter model reader and sampler, tracks and importance-weighted pairing."""

from __future__ import annotations

import dataclasses
import hashlib
import math
import tracemalloc

import numpy as np
import pytest
from scipy import stats

from uavxai.encounters import (
    NMAC_HMD,
    NMAC_VMD,
    EncounterConfig,
    InitialSample,
    Transitions,
    default_model,
    draw_miss_distances,
    load_model,
    parse_model,
    sample2track,
    sample_encounters,
    straight_ownship,
)
from uavxai.encounters.model import default_model_path
from uavxai.errors import UserError
from uavxai.units import KT

P_MIN = 1e-3  # a correct sampler fails a test with this probability at most (fixed seeds)


@pytest.fixture(scope="module")
def model():
    return default_model()


def chi_square_p(observed: np.ndarray, probabilities: np.ndarray) -> float:
    """Pearson's test, the bins expected under 5 counts pooled into one (or dropped when
    nothing at all is expected there and nothing was seen)."""
    n = observed.sum()
    expected = probabilities * n
    small = expected < 5
    if observed[expected == 0].sum() > 0:
        return 0.0
    obs = np.append(observed[~small], observed[small].sum())
    exp = np.append(expected[~small], expected[small].sum())
    if exp[-1] == 0:
        obs, exp = obs[:-1], exp[:-1]
    return float(stats.chisquare(obs, exp * obs.sum() / exp.sum()).pvalue)


def test_reading_gives_the_networks_em_read_gives(model) -> None:
    net, trans = model.initial, model.transition
    assert net.labels == ("G", "A", "L", "v", "\\dot v", "\\dot h", "\\dot \\psi")
    assert net.bins == (5, 4, 4, 8, 5, 7, 7)
    # G_initial is fully connected forward: variable i has parents 0..i-1.
    assert net.parents == tuple(tuple(range(i)) for i in range(7))
    assert [c.shape for c in net.counts] == [(5, 1), (4, 5), (4, 20), (8, 80), (5, 640),
                                             (7, 3200), (7, 22400)]
    # Every table counts the same observations.
    assert {c.sum() for c in net.counts} == {507_057_112.0}
    assert len(trans.labels) == 10 and trans.bins == (5, 4, 4, 8, 5, 7, 7, 5, 7, 7)
    assert trans.parents[7:] == ((2, 3, 4, 5, 6), (1, 2, 4, 5, 6), (2, 3, 4, 6))
    assert [c.shape for c in trans.counts[7:]] == [(5, 7840), (7, 3920), (7, 1120)]
    assert all(c is None for c in trans.counts[:7])
    assert model.temporal_map == ((4, 7), (5, 8), (6, 9))
    assert model.zero_bins == (None, None, None, None, 2, 3, 3)
    assert model.boundaries[2].tolist() == [50, 500, 1200, 3000, 5000]
    assert model.resample_rates[:2].tolist() == [0, 0]


def test_initial_marginals_match_the_network(model) -> None:
    exact = model.initial_marginals()
    draws = model.sample_initial(np.random.default_rng(20261127), 100_000)
    for i, p in enumerate(exact):
        assert p.sum() == pytest.approx(1.0)
        observed = np.bincount(draws.bins[:, i], minlength=len(p))
        assert chi_square_p(observed, p) > P_MIN, model.labels[i]


def test_a_wrong_table_fails_the_marginal_test(model) -> None:
    """The same test on a model whose airspeed table has two bins swapped must fail."""
    counts = list(model.initial.counts)
    counts[3] = counts[3][[0, 1, 2, 4, 3, 5, 6, 7]]  # 90-120 kt <-> 120-140 kt
    wrong = dataclasses.replace(model, initial=dataclasses.replace(model.initial,
                                                                   counts=tuple(counts)))
    draws = wrong.sample_initial(np.random.default_rng(20261127), 100_000)
    observed = np.bincount(draws.bins[:, 3], minlength=8)
    assert chi_square_p(observed, model.initial_marginals()[3]) < 1e-12


def test_one_second_transitions_match_the_table(model) -> None:
    """Turn rate at t+1 given (L, v, dv, dpsi) at t: a left turn of 1.5-4.5 deg/s."""
    state = {"G": 0, "A": 3, "L": 0, "v": 3, "\\dot v": 2, "\\dot h": 3, "\\dot \\psi": 2}
    rng = np.random.default_rng(7)
    initial = model.sample_initial(rng, 100_000, state)
    steps = model.sample_transitions(rng, initial, 2)
    i = 9  # \dot \psi(t+1)
    column = int(model.transition.column(i, initial.bins[:1])[0])
    table = model.transition.counts[i][:, column]
    assert table.sum() > 1000  # a configuration the data saw often
    observed = np.bincount(steps.bins[:, 1, 2], minlength=7)
    assert chi_square_p(observed, table / table.sum()) > P_MIN
    # and the test has teeth: the table of flying straight at t is far off
    # parents (L, v, dv, dpsi) with bins (4, 8, 5, 7): +160 is dpsi(t) bin 3 (straight)
    assert model.transition.parents[i] == (2, 3, 4, 6)
    other = model.transition.counts[i][:, column + 4 * 8 * 5]
    assert chi_square_p(observed, other / other.sum()) < 1e-12


def _hand_made(model, speed_kt: float, height_ft: float, dv: float, dh_fpm: float,
               dpsi: float, seconds: int) -> tuple[InitialSample, Transitions]:
    values = np.array([[1, 4, height_ft, speed_kt, dv, dh_fpm, dpsi]], dtype=float)
    initial = InitialSample(model.labels, np.zeros((1, 7), dtype=int), values)
    controls = np.tile([dv, dh_fpm, dpsi], (1, seconds, 1)).astype(float)
    labels = ("\\dot v", "\\dot h", "\\dot \\psi")
    return initial, Transitions(labels, np.zeros_like(controls, dtype=int), controls)


def test_track_units_are_si(model) -> None:
    initial, steps = _hand_made(model, 100, 300, 0, 600, 0, 10)
    track = sample2track(model, initial, steps)
    assert track.speed[0] == pytest.approx(51.444, abs=1e-3)  # 100 kt
    assert track.t.tolist() == list(range(11))
    assert track.y[10] == pytest.approx(514.44, abs=0.01) and abs(track.x[10]) < 1e-9  # north
    assert track.h[0] == pytest.approx(91.44) and track.vh[0] == pytest.approx(3.048)  # ft/min
    assert track.h[10] - track.h[0] == pytest.approx(30.48)
    accel = sample2track(model, *_hand_made(model, 100, 300, 1.0, 0, 0, 10))
    assert accel.speed[10] - accel.speed[0] == pytest.approx(10 * KT)  # 1 kt/s


def test_a_constant_turn_turns_at_its_rate(model) -> None:
    initial, steps = _hand_made(model, 90, 400, 0, 0, 3.0, 60)
    track = sample2track(model, initial, steps, steps_per_second=10)
    heading = np.unwrap(track.heading)
    assert np.allclose(np.diff(heading[::10]), math.radians(3.0))
    # on a circle of radius v / omega about a centre right of the start
    radius = 90 * KT / math.radians(3.0)
    dist = np.hypot(track.x - radius, track.y)
    assert np.abs(dist - radius).max() < 0.02 * radius


@pytest.fixture(scope="module")
def encounters(model):
    own = straight_ownship(speed=22.0, heading=0.6, height=120.0, tca=60.0)
    return {imp: sample_encounters(model, own, 40, seed=11, importance=imp)
            for imp in ("none", "nmac")}


def test_geometry_at_tca_matches_hmd_and_vmd(encounters) -> None:
    for e in encounters["none"] + encounters["nmac"]:
        k = int(e.tca)
        own = e.ownship.at(e.intruder.t[k], e.tca)
        rel = np.array([e.intruder.x[k] - own[0], e.intruder.y[k] - own[1]])
        assert abs(np.hypot(*rel) - e.hmd) < 1.0
        assert abs(e.intruder.h[k] - own[2] - e.vmd) < 1.0
        v_rel = np.array([e.intruder.vx[k] - e.ownship.velocity[0],
                          e.intruder.vy[k] - e.ownship.velocity[1]])
        assert abs(rel @ v_rel) < 1e-6 * max(1.0, np.hypot(*rel) * np.hypot(*v_rel))
        turn = e.intruder.heading[k] - math.atan2(*e.ownship.velocity[:2])
        assert math.remainder(turn - e.approach_angle, 2 * math.pi) == pytest.approx(0, abs=1e-9)
        assert 45 <= e.tca <= 75 and len(e.intruder.t) == 121


def test_weights_are_positive_and_finite(encounters) -> None:
    w = np.array([e.weight for e in encounters["nmac"]])
    assert np.all(np.isfinite(w)) and np.all(w > 0) and w.max() <= 4.0
    assert all(e.weight == 1.0 for e in encounters["none"])
    inside = [e for e in encounters["nmac"] if e.hmd < NMAC_HMD and abs(e.vmd) < NMAC_VMD]
    assert len(inside) >= 5  # the proposal does concentrate on NMACs (nominal: 1.6 %)


@pytest.mark.parametrize("hmd_nominal", ["uniform", "disc"])
def test_importance_weighted_nmac_rate_agrees_with_nominal(hmd_nominal) -> None:
    config = EncounterConfig(hmd_nominal=hmd_nominal)
    n = 200_000
    estimates = {}
    for k, imp in enumerate(("none", "nmac")):
        hmd, vmd, w = draw_miss_distances(np.random.default_rng(100 + k), n, imp, config)
        f = w * ((np.abs(hmd) < NMAC_HMD) & (np.abs(vmd) < NMAC_VMD))
        estimates[imp] = (f.mean(), f.std(ddof=1) / math.sqrt(n))
        if imp == "nmac":
            unweighted = ((np.abs(hmd) < NMAC_HMD) & (np.abs(vmd) < NMAC_VMD)).mean()
    (p0, s0), (p1, s1) = estimates["none"], estimates["nmac"]
    assert abs(p0 - p1) < 4 * math.hypot(s0, s1)
    assert s1 < s0 / 3  # importance sampling is what makes NMAC rates affordable
    share = (NMAC_HMD / 1852.0) ** (2 if hmd_nominal == "disc" else 1)
    exact = share * NMAC_VMD / 152.4
    assert abs(p1 - exact) < 4 * s1
    assert abs(unweighted - exact) > 100 * s1  # forgetting the weights would be caught


def test_the_same_seed_gives_the_same_encounters(model) -> None:
    own = straight_ownship(speed=22.0, heading=0.0, height=120.0, tca=60.0)
    a = sample_encounters(model, own, 3, seed=5, importance="nmac")
    b = sample_encounters(model, own, 3, seed=5, importance="nmac")
    c = sample_encounters(model, own, 3, seed=6, importance="nmac")
    for x, y in zip(a, b, strict=True):
        assert (x.seed, x.tca, x.hmd, x.vmd, x.weight) == (y.seed, y.tca, y.hmd, y.vmd, y.weight)
        assert np.array_equal(x.intruder.x, y.intruder.x)
    assert [x.hmd for x in a] != [x.hmd for x in c]


def _mutate(field: str, new: str) -> str:
    lines = default_model_path().read_text(encoding="ascii").splitlines()
    at = lines.index(f"# {field}") + 1
    lines[at] = new(lines[at]) if callable(new) else new
    return "\n".join(lines)


HOSTILE = {
    "huge bins": lambda: _mutate("r_initial", "5 4 4 8 5 7 200"),
    "huge bins everywhere": lambda: _mutate("r_transition", " ".join(["256"] * 10)),
    "NaN count": lambda: _mutate("N_initial", lambda s: "NaN " + s.split(" ", 1)[1]),
    "infinite count": lambda: _mutate("N_initial", lambda s: "1e999 " + s.split(" ", 1)[1]),
    "negative count": lambda: _mutate("N_initial", lambda s: "-3 " + s.split(" ", 1)[1]),
    "a count missing": lambda: _mutate("N_transition", lambda s: s.split(" ", 1)[1]),
    "a count too many": lambda: _mutate("N_transition", lambda s: "1 " + s),
    "a cycle": lambda: _mutate("G_initial", "0 1 1 1 1 1 1").replace(
        "0 0 0 0 0 0 0 \n# r_initial", "1 0 0 0 0 0 0\n# r_initial"),
    "G not 0/1": lambda: _mutate("G_initial", "0 2 1 1 1 1 1"),
    "code, not numbers": lambda: _mutate("resample_rates", "__import__('os') 0 0 0 0 0 0"),
    "rate above 1": lambda: _mutate("resample_rates", "0 0 0 0 0 0 1.5"),
    "falling boundaries": lambda: _mutate("boundaries", "*").replace(
        "50 500 1200 3000 5000", "50 500 400 3000 5000"),
    "unknown field": lambda: "# exec\nprint(1)\n" + default_model_path().read_text(),
    "nothing": lambda: "",
}


@pytest.mark.parametrize("case", sorted(HOSTILE))
def test_a_hostile_file_is_refused_without_allocating_much(case) -> None:
    text = HOSTILE[case]()
    tracemalloc.start()
    try:
        with pytest.raises(UserError):
            parse_model(text, name=case)
        peak = tracemalloc.get_traced_memory()[1]
    finally:
        tracemalloc.stop()
    assert peak < 100e6


def test_an_oversized_or_binary_file_is_refused(tmp_path) -> None:
    big = tmp_path / "big.txt"
    big.write_text("# labels_initial\n" + "1 " * 3_000_000)
    with pytest.raises(UserError, match="bytes"):
        load_model(big)
    binary = tmp_path / "bin.txt"
    binary.write_bytes(b"# labels_initial\n\xff\xfe")
    with pytest.raises(UserError, match="ASCII"):
        load_model(binary)
    with pytest.raises(UserError, match="cannot read"):
        load_model(tmp_path / "missing.txt")


def test_the_shipped_file_is_the_mit_ll_original() -> None:
    """Byte-identical to model/uncor_1200only_fwse_v1p2.txt of em-model-manned-bayes
    (data/README.md gives the commit), found next to the code as package data."""
    data = default_model_path().read_bytes()
    assert len(data) == 596_767
    assert hashlib.sha256(data).hexdigest() == (
        "a40e47d0cd0735055017f572036bba4fa30cc44b54a5eda256416d891b465786")
    assert (default_model_path().parent / "LICENSE").read_text().startswith("BSD 2-Clause")
