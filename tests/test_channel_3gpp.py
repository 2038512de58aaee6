"""The 3GPP TR 36.777 aerial channel models (comms.channel) against the standard's formulas.

Every hand number below was worked out from the formula in the comment beside it (TR 36.777
Annex B, Table B-1 LoS probability, Table B-2 path loss and shadow fading; f_c in GHz, d and
h in m, log = log10), not from the code. The geometry is a user at the origin of the region and
the UAV at horizontal distance d2D and height h, so d3D = sqrt(d2D^2 + h^2).
"""

from __future__ import annotations

import json
import math
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from uavxai.comms.channel import Channel
from uavxai.comms.delivery import Delivery
from uavxai.comms.pathloss import MODELS, LargeScale, Links, RMaAV, UMaAV, UMiAV, free_space_3gpp_db
from uavxai.errors import ScenarioError
from uavxai.scenario import default_scenario, load_scenario
from uavxai.vocabulary import CHANNEL_MODELS

UAVXAI = [sys.executable, "-m", "uavxai"]
USER = (1000.0, 1000.0)


def one_user(channel: str, carrier_ghz: float, **comms: object) -> Channel:
    users = {"positions": [list(USER)]}
    sc = default_scenario(
        comms={"channel": channel, "carrier_ghz": carrier_ghz, "users": users, **comms}
    )
    return Channel.from_scenario(sc)


def uav_at(d2d: float, h: float) -> np.ndarray:
    return np.array([USER[0] + d2d, USER[1], h])


# ------------------------------------------------------------------ tabulated points by hand
# (model, f_c GHz, d2D, h) -> (P_LoS, PL_LoS dB, PL_NLoS dB, sigma_LoS dB, sigma_NLoS dB)
HAND = {
    # UMa-AV, h = 50 m, d2D = 500 m, 2 GHz; d3D = sqrt(500^2 + 50^2) = 502.4938
    # d1 = max(460 log 50 - 700, 18) = 81.5262, p1 = 4300 log 50 - 3800 = 3505.571
    # P = 81.5262/500 + exp(-500/3505.571) (1 - 81.5262/500) = 0.163052 + 0.867077 * 0.836948
    # LoS:  28.0 + 22 log(502.4938) + 20 log(2) = 28 + 59.4249 + 6.0206 = 93.4455
    # NLoS: -17.5 + (46 - 7 log 50) log(502.4938) + 20 log(40 pi 2 / 3)
    #     = -17.5 + (46 - 11.8928) * 2.70113 + 38.4619 = 113.0904
    # sigma_LoS = 4.64 exp(-0.0066 * 50) = 3.33581; sigma_NLoS = 6
    ("uma_av", 2.0, 500.0, 50.0): (0.888749, 93.4455, 113.0904, 3.33581, 6.0),
    # UMi-AV, h = 100 m, d2D = 300 m, 2 GHz; d3D = 316.2278
    # d1 = max(294.05 * 2 - 432.94, 18) = 155.16, p1 = 233.98 * 2 - 0.95 = 467.01
    # P = 155.16/300 + exp(-300/467.01) (1 - 155.16/300) = 0.5172 + 0.526062 * 0.4828
    # PL_FS = 20 log(40 pi 316.2278 * 2 / 3) = 88.4624
    # fitted LoS = 30.9 + (22.25 - 0.5 * 2) log(316.2278) + 20 log 2 = 30.9 + 53.125 + 6.0206
    # LoS = max(88.4624, 90.0456) = 90.0456
    # NLoS = max(90.0456, 32.4 + (43.2 - 7.6 * 2) log(316.2278) + 20 log 2) = 108.4206
    # sigma_LoS = max(5 exp(-0.01 * 100), 2) = max(1.8394, 2) = 2 (the floor); NLoS 8
    ("umi_av", 2.0, 300.0, 100.0): (0.771170, 90.0456, 108.4206, 2.0, 8.0),
    # RMa-AV, h = 30 m, d2D = 1 km, 700 MHz; d3D = 1000.4499; 20 log(40 pi 0.7 / 3) = 29.3443
    # d1 = max(1350.8 log 30 - 1602, 18) = 393.2954, p1 = max(15021 log 30 - 16053, 1000)
    # = 6134.838; P = 0.3932954 + exp(-1000/6134.838) (1 - 0.3932954) = 0.908744
    # LoS = max(23.9 - 1.8 log 30, 20) log(1000.4499) + 29.3443 = 21.2412 * 3.000195 + 29.3443
    # NLoS = max(93.0714, -12 + (35 - 5.3 log 30) log(1000.4499) + 29.3443) = 98.8628
    # sigma_LoS = 4.2 exp(-0.0046 * 30) = 3.65861; NLoS 6
    ("rma_av", 0.7, 1000.0, 30.0): (0.908744, 93.0714, 98.8628, 3.65861, 6.0),
    # RMa-AV, h = 300 m, d2D = 100 m, 700 MHz: both maxima bind. P = 1 (h > 40 m).
    # 23.9 - 1.8 log 300 = 19.44 < 20, so the slope is 20 and LoS is free space:
    # d3D = 316.2278, PL = 20 log(316.2278) + 29.3443 = 79.3437
    # NLoS fitted = -12 + (35 - 5.3 log 300) * 2.5 + 29.3443 = 72.0219 < LoS: NLoS = LoS
    # sigma_LoS = 4.2 exp(-0.0046 * 300) = 1.05663
    ("rma_av", 0.7, 100.0, 300.0): (1.0, 79.3437, 79.3437, 1.05663, 6.0),
}


@pytest.mark.parametrize(("point", "expected"), HAND.items(), ids=lambda v: str(v))
def test_tabulated_point_by_hand(point, expected):
    model, fc, d2d, h = point
    ls = one_user(model, fc).large_scale(uav_at(d2d, h))
    p, los, nlos, sigma_los, sigma_nlos = expected
    assert float(ls.p_los[0]) == pytest.approx(p, abs=1e-6)
    assert float(ls.pl_los_db[0]) == pytest.approx(los, abs=1e-3)
    assert float(ls.pl_nlos_db[0]) == pytest.approx(nlos, abs=1e-3)
    assert float(ls.sigma_los_db[0]) == pytest.approx(sigma_los, abs=1e-5)
    assert float(ls.sigma_nlos_db[0]) == sigma_nlos


def test_umi_av_sigma_floor():
    # at 50 m the exponential is above the 2 dB floor: 5 exp(-0.5) = 3.03265; at 100 m below
    assert float(UMiAV().sigma_los_db(np.array(50.0))) == pytest.approx(3.03265, abs=1e-5)
    assert float(UMiAV().sigma_los_db(np.array(100.0))) == 2.0


# ------------------------------------------------------------------- limits and continuity
def test_los_probability_is_one_above_the_height_threshold():
    d2d = np.array([0.0, 50.0, 500.0, 2000.0, 4000.0])
    for model, above in ((UMaAV(), 100.0), (RMaAV(), 40.0)):
        for h in (above + 1e-6, above + 50.0, 300.0):
            np.testing.assert_array_equal(model.p_los(d2d, np.full(5, h)), 1.0)
        # just below it the formula still gives P < 1 far away
        assert model.p_los(np.array(4000.0), np.array(above)) < 1.0
    # UMi-AV has no such height: P < 1 far away even at 300 m
    assert UMiAV().p_los(np.array(4000.0), np.array(300.0)) < 1.0


@pytest.mark.parametrize("model", [UMaAV(), UMiAV(), RMaAV()], ids=lambda m: type(m).__name__)
def test_los_probability_is_one_within_d1_continuous_at_d1_and_falls_away(model):
    for h in (23.0, 35.0, 60.0, 90.0):
        hh = np.array(h)
        if model.p_los(np.array(1e4), hh) == 1.0:
            continue  # above the height threshold
        d = np.linspace(0.0, 4000.0, 4001)
        p = model.p_los(d, np.full_like(d, h))
        assert np.all(np.diff(p) <= 1e-12)  # non-increasing with distance
        assert p[0] == 1.0 and p[-1] < 1.0 and np.all((p > 0) & (p <= 1))
        # continuous where the formula starts: no jump between neighbouring metres
        assert np.abs(np.diff(p)).max() < 0.01


def test_nlos_is_never_below_los_where_the_standard_takes_the_max():
    d3d = np.geomspace(25.0, 10_000.0, 200)[:, None]
    h = np.linspace(22.6, 300.0, 60)[None, :]
    for model in (UMiAV(), RMaAV()):
        for fc in (0.7, 2.0, 6.0):
            los = model.pl_los_db(d3d, h, fc)
            assert np.all(model.pl_nlos_db(d3d, h, fc) >= los)
    # UMi-AV LoS is never below free space (its own max)
    assert np.all(UMiAV().pl_los_db(d3d, h, 2.0) >= free_space_3gpp_db(d3d, 2.0))


def test_carrier_enters_as_20_log10_fc_in_ghz():
    # doubling f_c adds 20 log 2 = 6.0206 dB to every 3GPP path loss
    for name in ("uma_av", "umi_av", "rma_av"):
        a = one_user(name, 1.0).large_scale(uav_at(400.0, 80.0))
        b = one_user(name, 2.0).large_scale(uav_at(400.0, 80.0))
        assert float(b.pl_los_db[0] - a.pl_los_db[0]) == pytest.approx(6.0206, abs=1e-4)
        assert float(b.pl_nlos_db[0] - a.pl_nlos_db[0]) == pytest.approx(6.0206, abs=1e-4)


def test_mean_path_loss_is_the_db_average_over_the_los_state():
    ch = one_user("uma_av", 2.0)
    # 0.888749 * 93.4455 + 0.111251 * 113.0904 = 95.6310 dB
    assert float(ch.path_loss_db(uav_at(500.0, 50.0))[0]) == pytest.approx(95.6310, abs=1e-3)
    assert float(ch.mean_gain(uav_at(500.0, 50.0))[0]) == pytest.approx(10**-9.56310, rel=1e-3)


# ------------------------------------------------------------------------------- shadowing
def test_shadowing_draws_have_the_tables_statistics():
    ch = one_user("uma_av", 2.0, fading="rayleigh", shadowing=True)
    ls = ch.large_scale(uav_at(500.0, 50.0))
    n = 200_000
    many = {
        k: np.broadcast_to(getattr(ls, k), (n, 1))
        for k in ("p_los", "los_db", "nlos_db", "sigma_los_db", "sigma_nlos_db")
    }
    big = LargeScale(base_db=0.0, **many)
    x = big.draw_db(np.random.default_rng(11))[:, 0]
    p, los, nlos = 0.888749, 93.4455, 113.0904
    # mean in dB: the mean path loss 95.6310; variance: p 3.33581^2 + (1 - p) 6^2
    # + p (1 - p) (113.0904 - 93.4455)^2 = 9.8896 + 4.0050 + 38.1581 = 52.0527
    var = p * 3.33581**2 + (1 - p) * 36.0 + p * (1 - p) * (nlos - los) ** 2
    assert var == pytest.approx(52.0527, abs=1e-3)
    se = math.sqrt(var / n)
    assert x.mean() == pytest.approx(95.6310, abs=4.5 * se)
    assert x.var() == pytest.approx(var, rel=0.02)  # about 5 standard errors


def test_seeded_draws_repeat_and_shadowing_comes_after_the_fading():
    plain = one_user("umi_av", 2.0, fading="rayleigh")
    shadow = one_user("umi_av", 2.0, fading="rayleigh", shadowing=True)
    uav = np.stack([uav_at(d, 60.0) for d in (50.0, 300.0, 900.0)])
    a = shadow.gain(uav, np.random.default_rng(3))
    np.testing.assert_array_equal(a, shadow.gain(uav, np.random.default_rng(3)))
    assert not np.array_equal(a, shadow.gain(uav, np.random.default_rng(4)))
    faded = plain.gain(uav, np.random.default_rng(3))
    # the fading stream is the same with shadowing on; the rest is the drawn large-scale factor
    h = plain.draw_fading(np.random.default_rng(3), faded.shape)
    np.testing.assert_array_equal(faded, plain.mean_gain(uav) * h)
    factor_db = 10.0 * np.log10(a / faded)
    assert np.all(np.isfinite(factor_db)) and np.abs(factor_db).max() > 0.1


def test_delivery_with_shadowing_is_finite_and_reproducible():
    sc = default_scenario(
        seed=2, comms={"channel": "rma_av", "fading": "rician", "shadowing": True}
    )
    ch = Channel.from_scenario(sc)
    t = np.arange(20) * 0.5
    uav = np.column_stack([1000 + 100 * np.cos(t), 1000 + 100 * np.sin(t), np.full(20, 35.0)])
    rows = [
        Delivery(ch, ch.equal_power(), rng=np.random.default_rng(9)).sample(t, uav, ch.users, 0.5)
        for _ in range(2)
    ]
    assert rows[0] == rows[1]
    rates = np.array(rows[0])[:, 4]
    assert np.all(np.isfinite(rates)) and np.all(rates > 0)


# ---------------------------------------------------------------------------- the scenario
SCENARIO = """\
name: standard-{model}
seed: 4
comms:
  channel: {model}
  fading: rayleigh
  shadowing: true
  users: {{count: 4, region: {{x: [900, 1100], y: [900, 1100]}}}}
world: {{h: [40, 160]}}
ownship: {{start: {{h: 100}}}}
intruders: {{altitude_m: [100, 140]}}
service: {{planner: random, steps: 30}}
"""


@pytest.mark.parametrize("model", [m for m, v in CHANNEL_MODELS.items() if v])
def test_a_scenario_selects_each_model_and_serves_finite_rates(tmp_path: Path, model: str):
    path = tmp_path / f"{model}.yaml"
    path.write_text(SCENARIO.format(model=model))
    sc = load_scenario(path)
    assert sc.comms.channel == model and sc.comms.shadowing
    ch = Channel.from_scenario(sc)
    assert ch.model == model and model in MODELS
    grid = np.stack(np.meshgrid([950.0, 1050.0], [1000.0], [40.0, 100.0, 160.0]), axis=-1)
    report = ch.evaluate(grid, ch.equal_power(), np.random.default_rng(0))
    assert np.all(np.isfinite(report.rate_bps)) and np.all(report.rate_bps > 0)
    # a different model gives a different channel at the same point
    other = replace(ch, model="al_hourani")
    assert np.abs(ch.path_loss_db(grid) - other.path_loss_db(grid)).max() > 1.0


def test_uavxai_service_runs_on_a_3gpp_scenario(tmp_path: Path):
    path = tmp_path / "uma.yaml"
    path.write_text(SCENARIO.format(model="uma_av"))
    out = tmp_path / "out"
    proc = subprocess.run(
        [*UAVXAI, "service", str(path), "--out", str(out)], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    # the report names the channel, and not Al-Hourani's environment that it does not use
    assert "uma_av, shared, rayleigh, shadowing" in proc.stdout
    assert "urban" not in proc.stdout
    summary = json.loads((out / "summary.json").read_text())
    assert summary["channel"] == "uma_av"
    rates = np.array(summary["rate_bps"], dtype=float)
    assert len(rates) == 4 and np.all(np.isfinite(rates))
    assert math.isfinite(summary["ergodic_sum_rate_bps"]) and summary["ergodic_sum_rate_bps"] > 0


@pytest.mark.parametrize(
    ("comms", "world", "words"),
    [
        ({"channel": "winner2"}, {}, ["comms.channel", "uma_av", "rma_av"]),
        ({"channel": "uma_av"}, {"h": [10, 300]}, ["uma_av", "22.5 m < h <= 300 m", "[10.0"]),
        ({"channel": "umi_av"}, {"h": [50, 400]}, ["umi_av", "300 m", "world.h"]),
        ({"channel": "rma_av"}, {"h": [10, 150]}, ["rma_av", "10 m < h"]),
        (
            {"channel": "uma_av"},
            {"x": [0, 5000], "y": [0, 5000]},
            ["4000 m", "comms.users.region", "world"],
        ),
        ({"shadowing": True}, {}, ["comms.shadowing", "al_hourani", "uma_av"]),
        ({"channel": "uma_av", "shadowing": True, "fading": "none"}, {}, ["fading", "rayleigh"]),
    ],
)
def test_bad_channel_settings_are_refused_clearly(comms, world, words):
    with pytest.raises(ScenarioError) as err:
        default_scenario(comms=comms, world=world)
    for word in words:
        assert word in str(err.value)


def test_validate_exits_2_without_a_traceback(tmp_path: Path):
    path = tmp_path / "low.yaml"
    path.write_text("name: low\ncomms: {channel: umi_av}\nworld: {h: [15, 300]}\n")
    proc = subprocess.run([*UAVXAI, "validate", str(path)], capture_output=True, text=True)
    assert proc.returncode == 2
    assert "umi_av" in proc.stderr and "22.5" in proc.stderr
    assert "Traceback" not in proc.stderr


def test_links_geometry_is_the_standards():
    links = Links.between(np.array([[30.0, 40.0, 120.0]]), np.zeros((1, 3)))
    # d2D = 50, d3D = sqrt(50^2 + 120^2) = 130, h = 120
    assert (float(links.d2d[0, 0]), float(links.d3d[0, 0]), float(links.h[0, 0])) == (
        50.0,
        130.0,
        120.0,
    )
