"""Air-to-ground channel of the seed paper (eqs 1-7), vectorised over users and positions.

A UAV at position ``(x, y, h)`` serves K ground users at ``(x_k, y_k, 0)``:

    d_k      = |uav - user_k|                                             (1)
    theta_k  = degrees(arcsin(h / d_k))                  elevation angle, in degrees
    P_LoS    = 1 / (1 + a exp(-b (theta_k - a)))         Al-Hourani et al. 2014
    L_k      = FSPL(d_k) + P_LoS eta_LoS + (1 - P_LoS) eta_NLoS    [dB]   (2)
    g_k      = H_k 10^(-L_k / 10)                                         (3)
    R_k      = B_k log2(1 + gamma_k)                                      (4)
    gamma_k  = v_k g_k p_k / (g_k sum_{i != k} v_i p_i + sigma_k^2)       (5)
    R        = sum_k R_k                                                  (6)
    R_T      = sum_t R(t)                                                 (7)

Every function broadcasts: a UAV position of shape ``(..., 3)`` against users ``(K, 3)`` gives
gains ``(..., K)``, so a whole grid of candidate positions is one call. Powers ``(..., K)``
broadcast against gains the same way.

Access modes. ``shared`` is the paper's single band: every user hears the signals meant for the
others through its own channel, hence the interference term ``g_k sum_{i != k} p_i`` — the SINR
is interference-limited and the placement matters little. ``ofdma`` gives each user B/K of the
band and sigma^2/K of the noise, with no intra-cell interference.

Small-scale fading H_k has unit mean: ``rayleigh`` is |CN(0, 1)|^2 (exponential), ``rician`` a
unit-power Rician with K-factor ``RICIAN_K_FACTOR_DB``, ``none`` is H_k = 1.

The large-scale model (P_LoS and the path loss of each state in eq 2) is ``comms.channel``:
the paper's Al-Hourani model above, or a 3GPP TR 36.777 aerial model (uavxai.comms.pathloss,
which also says why the mean path loss averages in dB). With ``comms.shadowing`` a 3GPP
channel's draws also draw each link's LoS state and log-normal shadowing, per user and per
position, wherever the fading is drawn (after it, from the same rng); the mean gain stays the
gain at the mean path loss (2).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Literal

import numpy as np

from uavxai.comms.pathloss import ENVIRONMENTS as ENVIRONMENTS
from uavxai.comms.pathloss import MODELS, LargeScale, Links
from uavxai.comms.pathloss import SPEED_OF_LIGHT_MPS as SPEED_OF_LIGHT_MPS
from uavxai.comms.pathloss import free_space_loss_db as free_space_loss_db
from uavxai.comms.pathloss import los_probability as los_probability
from uavxai.scenario import Comms, Scenario

RICIAN_K_FACTOR_DB = 10.0  # a strong specular path, typical of a UAV above the clutter

Fading = Literal["rayleigh", "rician", "none"]
Access = Literal["shared", "ofdma"]


def draw_users(scenario: Scenario) -> np.ndarray:
    """Ground users ``(K, 3)`` with h = 0: ``comms.users.positions`` if given, else uniform in
    ``comms.users.region`` from ``numpy.random.default_rng(scenario.seed)`` — the same seed
    always gives the same users, whatever else the scenario says."""
    users = scenario.comms.users
    if users.positions is not None:
        xy = np.asarray(users.positions, dtype=float).reshape(-1, 2)
    else:
        rng = np.random.default_rng(scenario.seed)
        lo = np.array([users.region.x[0], users.region.y[0]])
        hi = np.array([users.region.x[1], users.region.y[1]])
        xy = rng.uniform(lo, hi, size=(users.count, 2))
    return np.column_stack([xy, np.zeros(len(xy))])


@dataclass(frozen=True)
class Channel:
    """The channel of one scenario: K users' positions plus the link parameters (SI units)."""

    users: np.ndarray  # (K, 3), m
    carrier_hz: float
    bandwidth_hz: float
    noise_w: float  # sigma^2 of one user on the whole band
    environment: str
    fading: Fading
    access: Access
    p_max_w: float
    qos_rate_bps: float
    model: str = "al_hourani"  # comms.channel, a key of uavxai.comms.pathloss.MODELS
    shadowing: bool = False

    @classmethod
    def from_scenario(cls, scenario: Scenario, users: np.ndarray | None = None) -> Channel:
        c: Comms = scenario.comms
        return cls(
            users=draw_users(scenario) if users is None else np.asarray(users, dtype=float),
            carrier_hz=c.carrier_ghz * 1e9,
            bandwidth_hz=c.bandwidth_hz,
            noise_w=10.0 ** ((c.noise_dbm - 30.0) / 10.0),
            environment=c.environment,
            fading=c.fading,
            access=c.access,
            p_max_w=c.p_max_w,
            qos_rate_bps=c.qos_rate_bps,
            model=c.channel,
            shadowing=c.shadowing,
        )

    @property
    def k(self) -> int:
        return len(self.users)

    # ------------------------------------------------------------------ large-scale channel
    def geometry(self, uav: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Distance (m) and elevation angle (degrees) to each user: two arrays ``(..., K)``."""
        links = Links.between(uav, self.users)
        return links.d3d, links.elevation_deg

    def large_scale(self, uav: np.ndarray, users: np.ndarray | None = None) -> LargeScale:
        """P_LoS, path loss and shadowing sigma per state of each link ``(..., K)`` under
        ``comms.channel`` (``users`` default: the channel's)."""
        links = Links.between(uav, self.users if users is None else users)
        return MODELS[self.model].large_scale(links, self.carrier_hz / 1e9, self.environment)

    def p_los(self, uav: np.ndarray) -> np.ndarray:
        """The LoS probability of each link ``(..., K)`` under ``comms.channel``."""
        return self.large_scale(uav).p_los

    def path_loss_db(self, uav: np.ndarray) -> np.ndarray:
        """Mean path loss (2) in dB, ``(..., K)``."""
        return self.large_scale(uav).mean_db()

    def mean_gain(self, uav: np.ndarray) -> np.ndarray:
        """Gain (3) averaged over small-scale fading (H = 1), linear, ``(..., K)``."""
        return 10.0 ** (-self.path_loss_db(uav) / 10.0)

    # ------------------------------------------------------------------ small-scale fading
    def draw_fading(self, rng: np.random.Generator, shape: tuple[int, ...]) -> np.ndarray:
        """Unit-mean power fading coefficients H of the given shape."""
        if self.fading == "none":
            return np.ones(shape)
        if self.fading == "rayleigh":
            return rng.exponential(1.0, size=shape)
        k = 10.0 ** (RICIAN_K_FACTOR_DB / 10.0)
        los = np.sqrt(k / (k + 1.0))
        scatter = np.sqrt(1.0 / (2.0 * (k + 1.0)))
        re = los + scatter * rng.standard_normal(shape)
        im = scatter * rng.standard_normal(shape)
        return re**2 + im**2

    def draw_channel(
        self, rng: np.random.Generator, uav: np.ndarray, users: np.ndarray | None = None
    ) -> np.ndarray:
        """The factor ``(..., K)`` on the mean gain of the links from ``uav`` (..., 3): fading
        H, times, with ``shadowing``, 10^(-(PL_drawn - PL_mean) / 10) for a drawn LoS state and
        shadowing (drawn after H, so the fading stream is the same with or without it)."""
        users = self.users if users is None else users
        shape = np.shape(uav)[:-1] + (len(users),)
        h = self.draw_fading(rng, shape)
        if self.shadowing and self.fading != "none":
            ls = self.large_scale(uav, users)
            h = h * 10.0 ** (-(ls.draw_db(rng) - ls.mean_db()) / 10.0)
        return h

    def gain(self, uav: np.ndarray, rng: np.random.Generator | None = None) -> np.ndarray:
        """Instantaneous gain (3): the mean gain times fresh fading (and shadowing, if
        drawn) from ``rng`` (``rng=None`` or ``fading: none`` gives the mean gain)."""
        g = self.mean_gain(uav)
        if rng is None or self.fading == "none":
            return g
        return g * self.draw_channel(rng, uav)

    # ------------------------------------------------------------------ link budget
    def sinr(self, gain: np.ndarray, power_w: np.ndarray) -> np.ndarray:
        """SINR (5), linear, ``(..., K)``; zero for users given no power (v_k = 0)."""
        gain, power_w = np.broadcast_arrays(np.asarray(gain, float), np.asarray(power_w, float))
        if self.access == "shared":
            # The other users' signals reach user k through user k's own channel.
            interference = gain * (power_w.sum(axis=-1, keepdims=True) - power_w)
            noise = self.noise_w
        else:
            interference = 0.0
            noise = self.noise_w / self.k
        return gain * power_w / (interference + noise)

    def user_bandwidth_hz(self) -> float:
        return self.bandwidth_hz if self.access == "shared" else self.bandwidth_hz / self.k

    def rate(self, gain: np.ndarray, power_w: np.ndarray) -> np.ndarray:
        """Per-user rate (4) in bit/s, ``(..., K)``."""
        return self.user_bandwidth_hz() * np.log2(1.0 + self.sinr(gain, power_w))

    def objective(self, rate_bps: np.ndarray) -> np.ndarray:
        """The reward R(t) / 2^lambda: sum rate (6) halved for every user below the QoS rate."""
        lam = (rate_bps < self.qos_rate_bps).sum(axis=-1)
        return rate_bps.sum(axis=-1) / 2.0**lam

    def evaluate(
        self, uav: np.ndarray, power_w: np.ndarray, rng: np.random.Generator | None = None
    ) -> LinkReport:
        """Everything about serving from ``uav`` with ``power_w``, broadcasting over positions."""
        g = self.gain(uav, rng)
        gamma = self.sinr(g, power_w)
        rate = self.user_bandwidth_hz() * np.log2(1.0 + gamma)
        return LinkReport(gain=g, sinr=gamma, rate_bps=rate, objective=self.objective(rate))

    def sum_rate_bps(self, uav: np.ndarray, power_w: np.ndarray) -> np.ndarray:
        """The sum rate (6) from ``uav`` (3,) or positions (..., 3), without fading."""
        return self.evaluate(uav, power_w).sum_rate_bps

    def equal_power(self) -> np.ndarray:
        return np.full(self.k, self.p_max_w / self.k)


@dataclass(frozen=True)
class LinkReport:
    """Per-user arrays ``(..., K)`` and the objective ``(...)`` of one or many positions."""

    gain: np.ndarray
    sinr: np.ndarray
    rate_bps: np.ndarray
    objective: np.ndarray

    @property
    def sum_rate_bps(self) -> np.ndarray:
        return self.rate_bps.sum(axis=-1)

    @property
    def sinr_db(self) -> np.ndarray:
        with np.errstate(divide="ignore"):
            return 10.0 * np.log10(self.sinr)


def throughput_bits(rates_bps: np.ndarray, dt_s: float) -> float:
    """Throughput (7): the sum rate integrated over a sequence of service intervals."""
    return float(np.sum(np.asarray(rates_bps).sum(axis=-1)) * dt_s)
