"""The 3GPP TR 36.777 aerial channel models (comms.channel) against the standard's formulas.

Every hand number below was worked out from the standard's formula in the comment beside it,
not from the code: TR 36.777 V15.0.0 Annex B, Table B-1 LoS probability, Table B-2 path loss,
Table B-3 shadow-fading standard deviation (f_c in GHz, d and h in m, log = log10), as read in
the transcription MehdiZD97/3gpp-tr-library (TR-36.777/v15.0.0/annex-b-channel-modelling) and
cross-checked against two independent implementations (docs/channel-3gpp.md, "Sources"). The
geometry is a user at the origin of the region and the UAV at horizontal distance d2D and
height h, so d3D = sqrt(d2D^2 + h^2). Points sit inside each height band, at its edges (just
above the lower bound, on the inclusive upper bound, just past a P_LOS = 1 threshold) and at
the largest d2D each model holds for.
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
# 20 log(40 pi f_c / 3): 38.4624 at 2 GHz, 29.3437 at 700 MHz; 20 log 2 = 6.0206.
# (model, f_c GHz, d2D, h) -> (P_LoS, PL_LoS dB, PL_NLoS dB, sigma_LoS dB, sigma_NLoS dB).
# None where the standard has no row: the UMa-AV NLoS path loss and NLoS sigma stop at
# h = 100 m and RMa-AV's NLoS sigma at 40 m, the heights above which P_LOS = 1.
HAND = {
    # UMa-AV, h = 50 m, d2D = 500 m; d3D = 502.4938
    # d1 = max(460 log 50 - 700, 18) = 81.5262, p1 = 4300 log 50 - 3800 = 3505.571
    # P = 81.5262/500 + exp(-500/3505.571) (1 - 81.5262/500) = 0.163052 + 0.867077 * 0.836948
    # LoS:  28.0 + 22 log(502.4938) + 20 log(2) = 28 + 59.4249 + 6.0206 = 93.4455
    # NLoS: -17.5 + (46 - 7 log 50) log(502.4938) + 38.4624
    #     = -17.5 + (46 - 11.8928) * 2.70113 + 38.4624 = 113.0904
    # sigma_LoS = 4.64 exp(-0.0066 * 50) = 3.33581; sigma_NLoS = 6
    ("uma_av", 2.0, 500.0, 50.0): (0.888749, 93.4455, 113.0904, 3.33581, 6.0),
    # UMa-AV just above the band's lower edge, h = 23 m, d2D = 1 km; d3D = 1000.2645
    # d1 = max(460 log 23 - 700, 18) = max(-73.61, 18) = 18 (the floor binds)
    # p1 = 4300 * 1.361728 - 3800 = 2055.430; P = 0.018 + exp(-1000/2055.430) * 0.982
    #    = 0.018 + 0.614764 * 0.982 = 0.621699
    # LoS = 28 + 22 * 3.000115 + 6.0206 = 100.0231
    # NLoS = -17.5 + (46 - 7 * 1.361728) * 3.000115 + 38.4624 = 36.467905 * 3.000115 + 20.9624
    # sigma_LoS = 4.64 exp(-0.0066 * 23) = 3.98650
    ("uma_av", 2.0, 1000.0, 23.0): (0.621699, 100.0231, 130.3703, 3.98650, 6.0),
    # UMa-AV on the formula band's inclusive top, h = 100 m, d2D = 1 km; d3D = 1004.9876
    # d1 = 460 * 2 - 700 = 220, p1 = 4300 * 2 - 3800 = 4800
    # P = 0.22 + exp(-1000/4800) * 0.78 = 0.22 + 0.811936 * 0.78 = 0.853310
    # LoS = 28 + 22 * 3.002161 + 6.0206 = 100.0681
    # NLoS = -17.5 + (46 - 14) * 3.002161 + 38.4624 = 117.0315
    # sigma_LoS = 4.64 exp(-0.66) = 2.39819
    ("uma_av", 2.0, 1000.0, 100.0): (0.853310, 100.0681, 117.0315, 2.39819, 6.0),
    # UMa-AV just above 100 m: P_LOS = 100 % (Table B-1), so the NLoS rows end there.
    # d3D = 1005.0374: LoS = 28 + 22 log(1005.0374) + 6.0206 = 100.0686
    # sigma_LoS = 4.64 exp(-0.0066 * 100.5) = 2.39029
    ("uma_av", 2.0, 1000.0, 100.5): (1.0, 100.0686, None, 2.39029, None),
    # UMa-AV at the validity corner, h = 300 m, d2D = 4 km; d3D = 4011.2342, log = 3.603278
    # P = 1; LoS = 28 + 22 * 3.603278 + 6.0206 = 113.2927; sigma_LoS = 4.64 exp(-1.98) = 0.64064
    ("uma_av", 2.0, 4000.0, 300.0): (1.0, 113.2927, None, 0.64064, None),
    # UMa-AV inside d1: h = 90 m, d1 = 460 log 90 - 700 = 198.9516 > d2D = 198.9, so P = 1
    # d3D = 218.3145: LoS = 28 + 22 log(218.3145) + 6.0206 = 85.4804
    # NLoS = -17.5 + (46 - 7 log 90) log(218.3145) + 38.4624 = 96.5622
    # sigma_LoS = 4.64 exp(-0.594) = 2.56181
    ("uma_av", 2.0, 198.9, 90.0): (1.0, 85.4804, 96.5622, 2.56181, 6.0),
    # UMi-AV, h = 100 m, d2D = 300 m; d3D = 316.2278
    # d1 = max(294.05 * 2 - 432.94, 18) = 155.16, p1 = 233.98 * 2 - 0.95 = 467.01
    # P = 155.16/300 + exp(-300/467.01) (1 - 155.16/300) = 0.5172 + 0.526062 * 0.4828
    # PL' (free space) = 20 log(40 pi 316.2278 * 2 / 3) = 88.4624
    # fitted LoS = 30.9 + (22.25 - 0.5 * 2) log(316.2278) + 20 log 2 = 30.9 + 53.125 + 6.0206
    # LoS = max(88.4624, 90.0456) = 90.0456
    # NLoS = max(90.0456, 32.4 + (43.2 - 7.6 * 2) log(316.2278) + 20 log 2) = 108.4206
    # sigma_LoS = max(5 exp(-0.01 * 100), 2) = max(1.8394, 2) = 2 (the floor); NLoS 8
    ("umi_av", 2.0, 300.0, 100.0): (0.771170, 90.0456, 108.4206, 2.0, 8.0),
    # UMi-AV just above the lower edge, h = 23 m, d2D = 200 m; d3D = 201.3182, log = 2.303883
    # d1 = max(294.05 * 1.361728 - 432.94, 18) = max(-32.52, 18) = 18
    # p1 = 233.98 * 1.361728 - 0.95 = 317.6671; P = 0.09 + exp(-200/317.6671) * 0.91
    #    = 0.09 + 0.532810 * 0.91 = 0.574857
    # LoS = max(PL' = 84.5400, 30.9 + 21.569136 * 2.303883 + 6.0206 = 86.6134) = 86.6134
    # NLoS = max(86.6134, 32.4 + 32.850868 * 2.303883 + 6.0206 = 114.1052) = 114.1052
    # sigma_LoS = max(5 exp(-0.23), 2) = 3.97267
    ("umi_av", 2.0, 200.0, 23.0): (0.574857, 86.6134, 114.1052, 3.97267, 8.0),
    # UMi-AV at the validity corner, h = 300 m, d2D = 4 km; d3D = 4011.2342, log = 3.603278
    # d1 = 294.05 * 2.477121 - 432.94 = 295.4575, p1 = 233.98 * 2.477121 - 0.95 = 578.6468
    # P = 295.4575/4000 + exp(-4000/578.6468) (1 - 0.073864) = 0.073864 + 0.000995 * 0.926136
    # LoS = max(PL' = 110.5279, 30.9 + 21.011439 * 3.603278 + 6.0206 = 112.6307)
    # NLoS = max(112.6307, 32.4 + 24.373878 * 3.603278 + 6.0206 = 126.2465)
    # sigma_LoS = max(5 exp(-3), 2) = 2
    ("umi_av", 2.0, 4000.0, 300.0): (0.074786, 112.6307, 126.2465, 2.0, 8.0),
    # UMi-AV inside d1: h = 300 m, d1 = 295.4575 > d2D = 30 m, so P = 1 (UMi-AV never has
    # P = 1 for every d2D, but it does within d1). d3D = 301.4963, log = 2.479282
    # LoS = 30.9 + 21.011439 * 2.479282 + 6.0206 = 89.0139
    # NLoS = 32.4 + 24.373878 * 2.479282 + 6.0206 = 98.8503
    ("umi_av", 2.0, 30.0, 300.0): (1.0, 89.0139, 98.8503, 2.0, 8.0),
    # RMa-AV, h = 30 m, d2D = 1 km, 700 MHz; d3D = 1000.4499
    # d1 = max(1350.8 log 30 - 1602, 18) = 393.2954, p1 = max(15021 log 30 - 16053, 1000)
    # = 6134.838; P = 0.3932954 + exp(-1000/6134.838) (1 - 0.3932954) = 0.908744
    # LoS = max(23.9 - 1.8 log 30, 20) log(1000.4499) + 29.3437 = 21.2412 * 3.000195 + 29.3437
    # NLoS = max(93.0714, -12 + (35 - 5.3 log 30) log(1000.4499) + 29.3437) = 98.8628
    # sigma_LoS = 4.2 exp(-0.0046 * 30) = 3.65861; NLoS 6
    ("rma_av", 0.7, 1000.0, 30.0): (0.908744, 93.0714, 98.8628, 3.65861, 6.0),
    # RMa-AV just above the lower edge, h = 12 m, d2D = 500 m: both floors of Table B-1 bind,
    # d1 = max(1350.8 * 1.079181 - 1602, 18) = max(-144.2, 18) = 18 and
    # p1 = max(15021 * 1.079181 - 16053, 1000) = max(157.4, 1000) = 1000
    # P = 0.036 + exp(-0.5) * 0.964 = 0.036 + 0.606531 * 0.964 = 0.620696
    # d3D = 500.1440, log = 2.699095; slope = max(23.9 - 1.8 * 1.079181, 20) = 21.957474
    # LoS = 21.957474 * 2.699095 + 29.3437 = 88.6090
    # NLoS = max(88.6090, -12 + 29.280339 * 2.699095 + 29.3437 = 96.3742)
    # sigma_LoS = 4.2 exp(-0.0552) = 3.97444
    ("rma_av", 0.7, 500.0, 12.0): (0.620696, 88.6090, 96.3742, 3.97444, 6.0),
    # RMa-AV on the formula band's inclusive top, h = 40 m, d2D = 2 km; d3D = 2000.4000
    # d1 = 1350.8 * 1.602060 - 1602 = 562.0626, p1 = 15021 * 1.602060 - 16053 = 8011.543
    # P = 0.2810313 + exp(-2000/8011.543) (1 - 0.2810313) = 0.2810313 + 0.779081 * 0.7189687
    # slope = 23.9 - 1.8 * 1.602060 = 21.016292, log d3D = 3.301117
    # LoS = 21.016292 * 3.301117 + 29.3437 = 98.7210
    # NLoS = max(98.7210, -12 + 26.509082 * 3.301117 + 29.3437 = 104.8533)
    # sigma_LoS = 4.2 exp(-0.184) = 3.49413
    ("rma_av", 0.7, 2000.0, 40.0): (0.841166, 98.7210, 104.8533, 3.49413, 6.0),
    # RMa-AV just above 40 m: P_LOS = 100 %. d3D = 2000.4040
    # LoS = (23.9 - 1.8 log 40.2) log(2000.4040) + 29.3437 = 98.7081
    # NLoS = max(98.7081, -12 + (35 - 5.3 log 40.2) log(2000.4040) + 29.3437) = 104.8154
    # (the NLoS path-loss row runs to 300 m; its sigma stops at 40 m)
    # sigma_LoS = 4.2 exp(-0.0046 * 40.2) = 3.49092
    ("rma_av", 0.7, 2000.0, 40.2): (1.0, 98.7081, 104.8154, 3.49092, None),
    # RMa-AV at d2D = 10 km, h = 100 m; d3D = 10000.5000, log = 4.000022; P = 1
    # LoS = max(23.9 - 3.6, 20) * 4.000022 + 29.3437 = 20.3 * 4.000022 + 29.3437 = 110.5442
    # NLoS = max(110.5442, -12 + (35 - 10.6) * 4.000022 + 29.3437 = 114.9443)
    # sigma_LoS = 4.2 exp(-0.46) = 2.65139
    ("rma_av", 0.7, 10_000.0, 100.0): (1.0, 110.5442, 114.9443, 2.65139, None),
    # RMa-AV, h = 300 m, d2D = 100 m: both maxima bind. P = 1 (h > 40 m).
    # 23.9 - 1.8 log 300 = 19.44 < 20, so the slope is 20 and LoS is free space:
    # d3D = 316.2278, PL = 20 log(316.2278) + 29.3437 = 79.3437
    # NLoS fitted = -12 + (35 - 5.3 log 300) * 2.5 + 29.3437 = 72.0219 < LoS: NLoS = LoS
    # sigma_LoS = 4.2 exp(-0.0046 * 300) = 1.05663
    ("rma_av", 0.7, 100.0, 300.0): (1.0, 79.3437, 79.3437, 1.05663, None),
}


@pytest.mark.parametrize(("point", "expected"), HAND.items(), ids=lambda v: str(v))
def test_tabulated_point_by_hand(point, expected):
    model, fc, d2d, h = point
    ls = one_user(model, fc).large_scale(uav_at(d2d, h))
    p, los, nlos, sigma_los, sigma_nlos = expected
    assert float(ls.p_los[0]) == pytest.approx(p, abs=1e-6)
    assert float(ls.pl_los_db[0]) == pytest.approx(los, abs=1e-3)
    assert float(ls.sigma_los_db[0]) == pytest.approx(sigma_los, abs=1e-5)
    if nlos is not None:
        assert float(ls.pl_nlos_db[0]) == pytest.approx(nlos, abs=1e-3)
    if sigma_nlos is not None:
        assert float(ls.sigma_nlos_db[0]) == sigma_nlos
    else:
        # no NLoS row in the standard here: P_LOS = 1, so NLoS has no weight in the mean
        # path loss (2) and is never drawn
        assert p == 1.0 and float(ls.mean_db()[0]) == pytest.approx(los, abs=1e-3)


def test_umi_av_sigma_floor():
    # at 50 m the exponential is above the 2 dB floor: 5 exp(-0.5) = 3.03265; at 100 m below
    assert float(UMiAV().sigma_los_db(np.array(50.0))) == pytest.approx(3.03265, abs=1e-5)
    assert float(UMiAV().sigma_los_db(np.array(100.0))) == 2.0


def test_umi_av_los_is_floored_by_free_space():
    # Table B-2 Note 3: PL' is the free-space loss. Inside the range (d3D >= h > 22.5 m) the
    # fitted row is always the larger, so the floor is checked on the formula itself, at
    # d3D = 10 m, h = 300 m, 2 GHz: fitted = 30.9 + 21.011439 * 1 + 6.0206 = 57.9320 dB,
    # PL' = 20 log(40 pi 10 * 2 / 3) = 58.4624 dB, so PL_LoS = 58.4624
    los = UMiAV().pl_los_db(np.array(10.0), np.array(300.0), 2.0)
    assert float(los) == pytest.approx(58.4624, abs=1e-3)


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
