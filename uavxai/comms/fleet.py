"""The channel of a fleet: N UAVs serving K ground users, each user by one UAV (issue 32).

UAV n at ``q_n`` has the one-UAV channel's mean gain ``G[n, k]`` to user k (same path-loss
model, environment and carrier: ``Channel.mean_gain``). An association ``a`` gives each user
its serving UAV ``a_k``; integer power levels ``l_k`` in ``0..L-1`` map to watts per UAV, each
UAV with its own budget ``P_max,n`` (``levels_to_power`` over that UAV's users only):

    S_n  = sum_{k: a_k = n} l_k,     p_k = P_max,a_k l_k / max(S_{a_k}, L - 1),
    P_n  = sum_{k: a_k = n} p_k                          (UAV n's total transmit power)

Shared band. Besides the other users' signals of its own UAV (the one-UAV model: they reach
user k through its own channel), user k hears every other UAV's whole transmission through
that UAV's gain to k:

    gamma_k = G[a_k, k] p_k / (G[a_k, k] (P_{a_k} - p_k) + sum_{m != a_k} G[m, k] P_m + sigma^2)

OFDMA. The band is split between UAVs as well as users: every one of the K users has its own
slice B/K with noise sigma^2/K, so no user hears any other transmission:

    gamma_k = G[a_k, k] p_k / (sigma^2 / K),   R_k = (B / K) log2(1 + gamma_k)

Rates ``R_k = B_k log2(1 + gamma_k)`` and the objective is the paper's over all users,
``sum_k R_k / 2^lambda`` with lambda the users below the QoS rate (``Channel.objective``). With
N = 1 every quantity is the one-UAV channel's, bit for bit (tested).

Everything broadcasts over leading axes: positions ``(..., N, 3)`` give gains ``(..., N, K)``;
levels and associations ``(..., K)`` broadcast against them, so many candidate fleets are one
call.
"""

from __future__ import annotations

from dataclasses import dataclass, field, fields, replace

import numpy as np

from uavxai.comms.channel import Channel, LinkReport


def fleet_power(
    levels: np.ndarray, association: np.ndarray, p_max_w: np.ndarray, power_levels: int
) -> np.ndarray:
    """Watts ``(..., K)`` for levels ``(..., K)``: each UAV's ``levels_to_power`` over its own
    users, with its own ``p_max_w[n]``."""
    levels, association = np.broadcast_arrays(np.asarray(levels, float), np.asarray(association))
    n = len(p_max_w)
    member = association[..., None, :] == np.arange(n)[:, None]  # (..., N, K)
    totals = (member * levels[..., None, :]).sum(axis=-1)  # S_n, (..., N)
    served_total = np.take_along_axis(totals, association, axis=-1)
    # p_max * l / max(S, L-1) in the order levels_to_power computes it (N = 1: equal bits)
    return np.asarray(p_max_w)[association] * levels / np.maximum(served_total, power_levels - 1)


@dataclass(frozen=True)
class FleetChannel:
    """The one-UAV channel's users and link parameters, served by ``n`` UAVs."""

    channel: Channel
    p_max_w: np.ndarray  # (N,) each UAV's own budget, W

    @classmethod
    def of(cls, channel: Channel, n: int, p_max_w: np.ndarray | None = None) -> FleetChannel:
        budget = np.full(n, channel.p_max_w) if p_max_w is None else np.asarray(p_max_w, float)
        if budget.shape != (n,) or not np.all(budget > 0):
            raise ValueError(f"p_max_w must be {n} positive budgets, one per UAV; got {budget}")
        return cls(channel, budget)

    @property
    def n(self) -> int:
        return len(self.p_max_w)

    @property
    def k(self) -> int:
        return self.channel.k

    def gains(self, positions: np.ndarray) -> np.ndarray:
        """Mean (fading-free) gains ``(..., N, K)`` of UAV positions ``(..., N, 3)``."""
        return self.channel.mean_gain(np.asarray(positions, dtype=float))

    def power(self, levels: np.ndarray, association: np.ndarray, power_levels: int) -> np.ndarray:
        return fleet_power(levels, association, self.p_max_w, power_levels)

    def uav_power(self, power_w: np.ndarray, association: np.ndarray) -> np.ndarray:
        """Each UAV's total transmit power ``P_n``, ``(..., N)``."""
        member = np.asarray(association)[..., None, :] == np.arange(self.n)[:, None]
        return (member * np.asarray(power_w, float)[..., None, :]).sum(axis=-1)

    def sinr(self, gains: np.ndarray, association: np.ndarray, power_w: np.ndarray) -> np.ndarray:
        """SINR ``(..., K)`` for gains ``(..., N, K)`` (module docstring)."""
        power_w, association = np.broadcast_arrays(np.asarray(power_w, float), association)
        lead = np.broadcast_shapes(np.shape(gains)[:-2], association.shape[:-1])
        gains = np.broadcast_to(gains, lead + np.shape(gains)[-2:])
        power_w = np.broadcast_to(power_w, lead + power_w.shape[-1:])
        association = np.broadcast_to(association, lead + association.shape[-1:])
        served = np.take_along_axis(gains, association[..., None, :], axis=-2)[..., 0, :]
        if self.channel.access != "shared":
            return served * power_w / (self.channel.noise_w / self.k)
        totals = self.uav_power(power_w, association)  # (..., N)
        own = np.take_along_axis(totals, association, axis=-1)
        others = gains * totals[..., :, None]  # (..., N, K): every UAV's power at every user
        foreign = np.where(
            association[..., None, :] == np.arange(self.n)[:, None], 0.0, others
        ).sum(axis=-2)
        interference = served * (own - power_w) + foreign
        return served * power_w / (interference + self.channel.noise_w)

    def user_bandwidth_hz(self) -> float:
        return self.channel.user_bandwidth_hz()

    def evaluate_gains(
        self, gains: np.ndarray, association: np.ndarray, power_w: np.ndarray
    ) -> LinkReport:
        """Per-user gain from the serving UAV, SINR, rate ``(..., K)`` and objective."""
        gamma = self.sinr(gains, association, power_w)
        rate = self.user_bandwidth_hz() * np.log2(1.0 + gamma)
        gains = np.broadcast_to(gains, gamma.shape[:-1] + np.shape(gains)[-2:])
        which = np.broadcast_to(association, gamma.shape)[..., None, :]
        served = np.take_along_axis(gains, which, axis=-2)[..., 0, :]
        return LinkReport(served, gamma, rate, self.channel.objective(rate))

    def evaluate(
        self, positions: np.ndarray, association: np.ndarray, power_w: np.ndarray
    ) -> LinkReport:
        """Everything about the fleet at ``positions (..., N, 3)``, fading-free."""
        return self.evaluate_gains(self.gains(positions), association, power_w)

    def uav_channel(
        self, uav: int, gains: np.ndarray, association: np.ndarray, power_w: np.ndarray
    ) -> InterferedChannel:
        """The one-UAV problem of UAV ``uav`` with every other UAV fixed: its own users, its
        budget, and (shared band) the other UAVs' power at each of them, as a one-UAV
        :class:`Channel` whose SINR (5) is the fleet's for those users."""
        association = np.asarray(association)
        mine = association == uav
        c = self.channel
        scale = mine.sum() / self.k  # OFDMA: the users keep their slices B/K and sigma^2/K
        extra = np.zeros(int(mine.sum()))
        if c.access == "shared":
            totals = self.uav_power(power_w, association)
            others = np.delete(np.arange(self.n), uav)
            extra = (gains[others][:, mine] * totals[others][:, None]).sum(axis=0)
        sub = replace(
            c,
            users=c.users[mine],
            p_max_w=float(self.p_max_w[uav]),
            bandwidth_hz=c.bandwidth_hz * (1.0 if c.access == "shared" else scale),
            noise_w=c.noise_w * (1.0 if c.access == "shared" else scale),
        )
        values = {f.name: getattr(sub, f.name) for f in fields(sub)}
        return InterferedChannel(**values, interference_w=extra)


@dataclass(frozen=True)
class InterferedChannel(Channel):
    """A one-UAV channel whose users also hear a fixed interference power ``I_k`` (W) from
    other transmitters, folded into an effective gain ``g_k sigma^2 / (sigma^2 + I_k)``: then
    eq (5), ``g' p_k / (g' sum_{i!=k} p_i + sigma^2) = p_k / (sum_{i!=k} p_i + (sigma^2 +
    I_k) / g_k)``, is the SINR with the interference, so every one-UAV planner (the exact
    ``grid``, the local search) solves the fleet's per-UAV problem unchanged. In OFDMA ``I``
    is zero and the gain is the channel's."""

    interference_w: np.ndarray = field(default_factory=lambda: np.zeros(0))

    def mean_gain(self, uav: np.ndarray) -> np.ndarray:
        g = super().mean_gain(uav)
        if not np.any(self.interference_w):
            return g
        return g * (self.noise_w / (self.noise_w + self.interference_w))
