"""Large-scale air-to-ground channel models, a registry by name (scenario ``comms.channel``).

Each model gives, per link, the LoS probability, the LoS and NLoS path losses and the
shadow-fading standard deviation of each state (:class:`LargeScale`). The mean path loss the
planners use is the same for every model:

    L = P_LoS PL_LoS + (1 - P_LoS) PL_NLoS                                   [dB]

the paper's eq (2). It averages in dB, over the LoS state and over the zero-mean (in dB)
shadowing: the gain at that mean is the median-like gain of the link, not its linear-power
mean. Two reasons. It is how the paper and Al-Hourani et al. average (eq 2 weighs the excess
losses in dB), so switching models changes the channel, not the meaning of "mean gain"; and a
linear-power mean would let the rare deep LoS draws and the log-normal tail (10^(sigma^2
ln10 / 200): +4.1 dB for sigma = 6 dB) lift the gain of links that are NLoS most of the time,
so a planner would place the UAV for a channel it seldom sees. The rates, being logarithmic in
the gain, are nearer the dB average too.

``al_hourani`` is the paper's model (uavxai.comms.channel): P_LoS from the elevation angle,
PL = FSPL + eta_LoS or eta_NLoS, no shadowing. The three 3GPP models are those of TR 36.777
V15.0.0 Annex B (aerial vehicles, extending TR 38.901 Table 7.4.1-1 / 7.4.2-1 to aerial
heights): Table B-1 the LoS probability, Table B-2 the path loss, Table B-3 the shadow-fading
sigma, written below with their table references and checked coefficient by coefficient
against the sources listed in docs/channel-3gpp.md. Conventions of the standard: f_c in GHz,
distances and heights in m; ``h`` is h_UT, the aerial node's height. Here the UAV is the base
station and the users are the ground nodes; the link is reciprocal, so h_UT is the UAV's height
above the user, d2D the horizontal and d3D the straight-line distance between them. Table B-1
was fitted with the ground node on a mast (its Note 1: 35 m RMa-AV, 25 m UMa-AV, 10 m UMi-AV);
a user on the ground sits lower, a difference the standard offers no correction for.

Validity (uavxai.vocabulary.CHANNEL_MODELS): UMa-AV and UMi-AV 22.5 m < h <= 300 m and
d2D <= 4 km, RMa-AV 10 m < h <= 300 m and d2D <= 10 km. Below those heights TR 36.777 sends
the aerial UE back to TR 38.901's terrestrial formulas; those are not offered here but
refused (at scenario load, where world.h is known): they model a handset below a base station
on a mast (25 m UMa, 10 m UMi, 35 m RMa), with breakpoint distances built from the mast's
height. With the UAV as the base station and the user on the ground there is no mast, so
their breakpoint has no meaning, and a UAV below the rooftops is not the aerial base station
these models describe. The formulas here are evaluated wherever they are asked (a planner
probes points one step outside its search box and masks them); the scenario guarantees that
every point a UAV flies at lies inside the range.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from dataclasses import dataclass
from typing import Protocol

import numpy as np

from uavxai.vocabulary import CHANNEL_MODEL_NAMES

SPEED_OF_LIGHT_MPS = 299_792_458.0

# Al-Hourani's fitted S-curve (a, b) and the excess losses (eta_LoS, eta_NLoS) in dB.
ENVIRONMENTS: dict[str, tuple[float, float, float, float]] = {
    "suburban": (4.88, 0.43, 0.1, 21.0),
    "urban": (9.61, 0.16, 1.0, 20.0),
    "dense_urban": (12.08, 0.11, 1.6, 23.0),
    "highrise_urban": (27.23, 0.08, 2.3, 34.0),
}


@dataclass(frozen=True)
class Links:
    """The geometry of UAV-user links, arrays ``(..., K)``: horizontal and straight-line
    distances (m), the UAV's height above each user (m) and the elevation angle (degrees)."""

    d2d: np.ndarray
    d3d: np.ndarray
    h: np.ndarray
    elevation_deg: np.ndarray

    @classmethod
    def between(cls, uav: np.ndarray, users: np.ndarray) -> Links:
        delta = np.asarray(uav, dtype=float)[..., None, :] - users  # (..., K, 3)
        d3d = np.linalg.norm(delta, axis=-1)
        elevation = np.degrees(np.arcsin(np.clip(delta[..., 2] / d3d, -1.0, 1.0)))
        return cls(np.hypot(delta[..., 0], delta[..., 1]), d3d, delta[..., 2], elevation)


@dataclass(frozen=True)
class LargeScale:
    """Per link ``(..., K)``: LoS probability, path loss per state (dB) and the shadow-fading
    standard deviation per state (dB). A state's path loss is ``base_db`` plus its own term:
    Al-Hourani's base is the free-space loss and the terms its excess losses eta; the 3GPP
    models have base 0 and the whole path loss in the terms."""

    p_los: np.ndarray
    base_db: np.ndarray | float
    los_db: np.ndarray
    nlos_db: np.ndarray
    sigma_los_db: np.ndarray
    sigma_nlos_db: np.ndarray

    @property
    def pl_los_db(self) -> np.ndarray:
        return self.base_db + self.los_db

    @property
    def pl_nlos_db(self) -> np.ndarray:
        return self.base_db + self.nlos_db

    def mean_db(self) -> np.ndarray:
        """The mean path loss (2), averaged in dB over the LoS state (module docstring):
        base + P_LoS los + (1 - P_LoS) nlos, the paper's order of operations."""
        return self.base_db + self.p_los * self.los_db + (1.0 - self.p_los) * self.nlos_db

    def draw_db(self, rng: np.random.Generator) -> np.ndarray:
        """One realised path loss per link: the LoS state drawn with P_LoS, then log-normal
        shadowing of that state's sigma. Its mean in dB is :meth:`mean_db`."""
        los = rng.random(self.p_los.shape) < self.p_los
        sigma = np.where(los, self.sigma_los_db, self.sigma_nlos_db)
        shadow = sigma * rng.standard_normal(self.p_los.shape)
        return np.where(los, self.pl_los_db, self.pl_nlos_db) + shadow


class ChannelModel(Protocol):
    def large_scale(self, links: Links, carrier_ghz: float, environment: str) -> LargeScale:
        """The large-scale channel of each link (``environment`` is Al-Hourani's only)."""
        ...


def free_space_loss_db(distance_m: np.ndarray, carrier_hz: float) -> np.ndarray:
    """20 log10(4 pi f_c d / c)."""
    return 20.0 * np.log10(4.0 * np.pi * carrier_hz * distance_m / SPEED_OF_LIGHT_MPS)


def los_probability(elevation_deg: np.ndarray, environment: str) -> np.ndarray:
    """Al-Hourani's LoS probability; the fit takes the elevation angle in degrees."""
    a, b, _, _ = ENVIRONMENTS[environment]
    return 1.0 / (1.0 + a * np.exp(-b * (elevation_deg - a)))


class AlHourani:
    """The paper's model: PL_LoS/NLoS = FSPL(d3D) + eta_LoS/NLoS, P_LoS = S-curve of the
    elevation angle (Al-Hourani et al. 2014), no shadowing."""

    def large_scale(self, links: Links, carrier_ghz: float, environment: str) -> LargeScale:
        _, _, eta_los, eta_nlos = ENVIRONMENTS[environment]
        fspl = free_space_loss_db(links.d3d, carrier_ghz * 1e9)
        zero = np.zeros_like(fspl)
        p = los_probability(links.elevation_deg, environment)
        return LargeScale(p, fspl, zero + eta_los, zero + eta_nlos, zero, zero)


# ------------------------------------------------------------------------- 3GPP TR 36.777
def log10(x: np.ndarray | float) -> np.ndarray:
    return np.log10(np.asarray(x, dtype=float))


def los_probability_d1_p1(d2d: np.ndarray, d1: np.ndarray, p1: np.ndarray) -> np.ndarray:
    """The aerial LoS probability form of TR 36.777 Table B-1:

        P_LOS = 1                                          d2D <= d1
        P_LOS = d1/d2D + exp(-d2D/p1) (1 - d1/d2D)         d2D > d1
    """
    far = np.maximum(d2d, d1)  # d2D <= d1 gives d1/d1 + ... (1 - 1) = 1 exactly
    return d1 / far + np.exp(-far / p1) * (1.0 - d1 / far)


def free_space_1m_db(fc_ghz: float) -> float:
    """20 log10(40 pi f_c / 3): the free-space loss at 1 m with f_c in GHz (4 pi f / c =
    40 pi f_c / 3 per m), the term TR 36.777 and TR 38.901 write in their formulas."""
    return float(20.0 * np.log10(40.0 * np.pi * fc_ghz / 3.0))


def free_space_3gpp_db(d3d: np.ndarray, fc_ghz: float) -> np.ndarray:
    """PL_FS = 20 log10(40 pi d3D f_c / 3), the free-space loss (f_c in GHz, d3D in m). TR
    36.777 Table B-2 names UMi-AV's floor only "PL', the free space path loss" (its Note 3);
    this is that loss in the form its RMa-AV rows write, 20 log10(40 pi f_c / 3) at 1 m."""
    return 20.0 * log10(d3d) + free_space_1m_db(fc_ghz)


class AerialModel(ABC):
    """A TR 36.777 Annex B model: its LoS probability, path loss per state and shadow-fading
    sigma per state (the NLoS sigma is a constant in every row of Table B-3), as one LargeScale.

    Where the table sets P_LOS = 1 (UMa-AV above 100 m, RMa-AV above 40 m) it has no NLoS
    sigma, and UMa-AV no NLoS path loss either; the NLoS formulas are still evaluated there
    (one array for every link) but carry the weight 1 - P_LOS = 0 in the mean and are never
    drawn."""

    sigma_nlos: float

    @abstractmethod
    def p_los(self, d2d: np.ndarray, h: np.ndarray) -> np.ndarray: ...

    @abstractmethod
    def pl_los_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray: ...

    @abstractmethod
    def pl_nlos_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray: ...

    @abstractmethod
    def sigma_los_db(self, h: np.ndarray) -> np.ndarray: ...

    def large_scale(self, links: Links, carrier_ghz: float, environment: str) -> LargeScale:
        h, d3d = links.h, links.d3d
        return LargeScale(
            p_los=self.p_los(links.d2d, h),
            base_db=0.0,
            los_db=self.pl_los_db(d3d, h, carrier_ghz),
            nlos_db=self.pl_nlos_db(d3d, h, carrier_ghz),
            sigma_los_db=self.sigma_los_db(h),
            sigma_nlos_db=np.full(np.shape(h), self.sigma_nlos),
        )


class UMaAV(AerialModel):
    """Urban macro, aerial (TR 36.777 Tables B-1, B-2, B-3), 22.5 m < h <= 300 m, d2D <= 4 km.

    LoS probability (Table B-1):
        22.5 m < h <= 100 m:  d1 = max(460 log10 h - 700, 18), p1 = 4300 log10 h - 3800,
                              P_LOS by :func:`los_probability_d1_p1`
        100 m < h <= 300 m:   P_LOS = 1
    Path loss (Table B-2) and shadow-fading sigma (Table B-3):
        LoS:  PL = 28.0 + 22 log10 d3D + 20 log10 f_c,         sigma_SF = 4.64 exp(-0.0066 h)
              (no breakpoint for 22.5 m <= h <= 300 m, d2D <= 4 km: Table B-2 Note 1)
        NLoS: PL = -17.5 + (46 - 7 log10 h) log10 d3D + 20 log10(40 pi f_c / 3),  sigma_SF = 6
              (rows for h <= 100 m only, where P_LOS < 1 can occur)
    (the NLoS row has no max(PL_LoS, ...) in the table, unlike UMi-AV and RMa-AV).
    """

    sigma_nlos = 6.0

    def p_los(self, d2d: np.ndarray, h: np.ndarray) -> np.ndarray:
        d1 = np.maximum(460.0 * log10(h) - 700.0, 18.0)
        p1 = 4300.0 * log10(h) - 3800.0
        return np.where(h > 100.0, 1.0, los_probability_d1_p1(d2d, d1, p1))

    def pl_los_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray:
        return 28.0 + 22.0 * log10(d3d) + 20.0 * log10(fc_ghz)

    def pl_nlos_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray:
        return -17.5 + (46.0 - 7.0 * log10(h)) * log10(d3d) + free_space_1m_db(fc_ghz)

    def sigma_los_db(self, h: np.ndarray) -> np.ndarray:
        return 4.64 * np.exp(-0.0066 * np.asarray(h, dtype=float))


class UMiAV(AerialModel):
    """Urban micro, aerial (TR 36.777 Tables B-1, B-2, B-3), 22.5 m < h <= 300 m, d2D <= 4 km.

    LoS probability (Table B-1), over the whole aerial range (never 1 for every d2D):
        d1 = max(294.05 log10 h - 432.94, 18), p1 = 233.98 log10 h - 0.95,
        P_LOS by :func:`los_probability_d1_p1`
    Path loss (Table B-2) and shadow-fading sigma (Table B-3), PL_FS the free-space loss
    (:func:`free_space_3gpp_db`):
        LoS:  PL = max(PL_FS, 30.9 + (22.25 - 0.5 log10 h) log10 d3D + 20 log10 f_c),
              sigma_SF = max(5 exp(-0.01 h), 2)
        NLoS: PL = max(PL_LoS, 32.4 + (43.2 - 7.6 log10 h) log10 d3D + 20 log10 f_c),
              sigma_SF = 8
    Inside the range (d3D >= h > 22.5 m) neither max binds; they are kept as the table writes
    them.
    """

    sigma_nlos = 8.0

    def p_los(self, d2d: np.ndarray, h: np.ndarray) -> np.ndarray:
        d1 = np.maximum(294.05 * log10(h) - 432.94, 18.0)
        p1 = 233.98 * log10(h) - 0.95
        return los_probability_d1_p1(d2d, d1, p1)

    def pl_los_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray:
        fitted = 30.9 + (22.25 - 0.5 * log10(h)) * log10(d3d) + 20.0 * log10(fc_ghz)
        return np.maximum(free_space_3gpp_db(d3d, fc_ghz), fitted)

    def pl_nlos_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray:
        fitted = 32.4 + (43.2 - 7.6 * log10(h)) * log10(d3d) + 20.0 * log10(fc_ghz)
        return np.maximum(self.pl_los_db(d3d, h, fc_ghz), fitted)

    def sigma_los_db(self, h: np.ndarray) -> np.ndarray:
        return np.maximum(5.0 * np.exp(-0.01 * np.asarray(h, dtype=float)), 2.0)


class RMaAV(AerialModel):
    """Rural macro, aerial (TR 36.777 Tables B-1, B-2, B-3), 10 m < h <= 300 m, d2D <= 10 km.

    LoS probability (Table B-1):
        10 m < h <= 40 m:   d1 = max(1350.8 log10 h - 1602, 18),
                            p1 = max(15021 log10 h - 16053, 1000),
                            P_LOS by :func:`los_probability_d1_p1`
        40 m < h <= 300 m:  P_LOS = 1
    Path loss (Table B-2) and shadow-fading sigma (Table B-3), no breakpoint above 10 m:
        LoS:  PL = max(23.9 - 1.8 log10 h, 20) log10 d3D + 20 log10(40 pi f_c / 3),
              sigma_SF = 4.2 exp(-0.0046 h)
        NLoS: PL = max(PL_LoS, -12 + (35 - 5.3 log10 h) log10 d3D + 20 log10(40 pi f_c / 3)),
              sigma_SF = 6 (Table B-3 gives it for h <= 40 m only, where P_LOS < 1 can occur)
    """

    sigma_nlos = 6.0

    def p_los(self, d2d: np.ndarray, h: np.ndarray) -> np.ndarray:
        d1 = np.maximum(1350.8 * log10(h) - 1602.0, 18.0)
        p1 = np.maximum(15021.0 * log10(h) - 16053.0, 1000.0)
        return np.where(h > 40.0, 1.0, los_probability_d1_p1(d2d, d1, p1))

    def pl_los_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray:
        slope = np.maximum(23.9 - 1.8 * log10(h), 20.0)
        return slope * log10(d3d) + free_space_1m_db(fc_ghz)

    def pl_nlos_db(self, d3d: np.ndarray, h: np.ndarray, fc_ghz: float) -> np.ndarray:
        fitted = -12.0 + (35.0 - 5.3 * log10(h)) * log10(d3d) + free_space_1m_db(fc_ghz)
        return np.maximum(self.pl_los_db(d3d, h, fc_ghz), fitted)

    def sigma_los_db(self, h: np.ndarray) -> np.ndarray:
        return 4.2 * np.exp(-0.0046 * np.asarray(h, dtype=float))


MODELS: dict[str, ChannelModel] = {
    "al_hourani": AlHourani(),
    "uma_av": UMaAV(),
    "umi_av": UMiAV(),
    "rma_av": RMaAV(),
}
# The scenario's names (uavxai.vocabulary) and this registry are one list.
assert tuple(MODELS) == CHANNEL_MODEL_NAMES, "comms.channel names and MODELS differ"
