"""Delivered service: what the users actually got from the positions the aircraft flew.

Each sample is one logged instant ``t`` that stands for the interval ``dt`` after it (the
rectangle rule the recorder's rows imply: a run logged at 10 Hz integrates with dt = 0.1 s).
At that instant the channel of ``channel.py`` is evaluated from the flown UAV position to the
users' current positions (they may walk), with small-scale fading H drawn afresh for every
(sample, user) from the accumulator's seeded generator:

    g_k(t)   = H_k(t) 10^(-L_k(t) / 10)                 (3), L_k from the flown geometry (2)
    R_k(t)   = B_k log2(1 + gamma_k(t))                 (4)-(5), with the allocation p(t)
    bits_k  += R_k(t) dt                                (7), per user

and accumulated:

- ``delivered_bits`` and ``delivered_bits_per_user`` [K];
- ``qos_user_seconds_share``: sum of dt over (sample, user) with R_k >= qos_rate_bps, over
  K times the time sampled (a user given no power counts as not meeting it);
- ``jain_fairness`` of the per-user delivered bits, (sum x)^2 / (K sum x^2): 1 when everybody
  got the same, 1/K when one user got everything; 0 when nothing was delivered at all;
- ``avoidance_lost_bits``: over the samples flagged ``avoiding`` that give ``planned_pos`` (the
  point of the planned orbit at that instant), the bits the planned point would have delivered
  minus those delivered, with the SAME fading draw for both, so the difference is the
  manoeuvre's alone and not fading noise. It can be negative (an escape that passes closer to
  the users).

The fading stream is consumed identically whether or not a sample is avoiding and whether the
samples come one by one or as a batch, so the same seed gives the same ``service.csv``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from uavxai.comms.channel import Channel
from uavxai.errors import UserError

SERVICE_COLUMNS = ("t", "user", "power_w", "sinr_db", "rate_bps", "uav")
USERS_COLUMNS = ("t", "user", "x", "y")

ServiceRow = tuple[float, int, float, float, float]


def jain_fairness(bits: np.ndarray) -> float:
    """Jain's fairness of the per-user delivered ``bits``, (sum x)^2 / (K sum x^2): 1 when
    everybody got the same, 1/K when one user got everything, 0 when nothing was delivered."""
    bits = np.asarray(bits, dtype=float)
    square = float((bits**2).sum())
    return float(bits.sum()) ** 2 / (len(bits) * square) if square > 0 else 0.0


def service_lines(rows: list[ServiceRow], uav: int = 0, users: np.ndarray | None = None) -> str:
    """``rows`` as service.csv's lines, served by ``uav``; ``users`` maps a row's user (an
    index into the serving UAV's own users) to the crowd's (None: the same)."""
    def k(r: ServiceRow) -> int:
        return r[1] if users is None else int(users[r[1]])

    return "".join(f"{r[0]:.3f},{k(r)},{r[2]:.6g},{r[3]:.4f},{r[4]:.6g},{uav}\n" for r in rows)


def user_positions(channel: Channel, users_pos: np.ndarray) -> np.ndarray:
    """``users_pos`` as an array ``(K, 3)`` or ``(N, K, 3)``, or a clear error."""
    users = np.asarray(users_pos, dtype=float)
    if users.shape[-2:] != (channel.k, 3):
        raise UserError(
            f"user positions must be (K, 3) or (N, K, 3) with K = {channel.k}, got shape "
            f"{users.shape}"
        )
    return users


def rates_at(
    channel: Channel,
    uav_pos: np.ndarray,
    users_pos: np.ndarray,
    power_w: np.ndarray,
    fading: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """SINR (linear) and rate (bit/s), ``(N, K)``, from UAV positions ``(N, 3)`` to users
    ``(N, K, 3)`` (or ``(K, 3)`` shared by all samples), with fading ``(N, K)`` (None: H = 1).

    ``channel.users`` is not used: the geometry is the users' current positions; everything
    else (carrier, environment, noise, access, K) is the channel's.
    """
    uav = np.asarray(uav_pos, dtype=float).reshape(-1, 3)
    users = user_positions(channel, users_pos)
    # Channel.geometry broadcasts uav (N, 1, 3) against its users; give it per-sample users
    # through a copy (frozen dataclass) that is only used for the path loss.
    moved = replace(channel, users=users)
    gain = moved.mean_gain(uav)  # (N, K)
    if fading is not None:
        gain = gain * fading
    sinr = channel.sinr(gain, power_w)
    return sinr, channel.user_bandwidth_hz() * np.log2(1.0 + sinr)


@dataclass(frozen=True)
class ServiceSample:
    """One call's samples: arrays ``(N, K)`` (``t``, ``dt``, ``avoiding`` are ``(N,)``)."""

    t: np.ndarray
    dt: np.ndarray
    power_w: np.ndarray
    sinr_db: np.ndarray  # -inf for users given no power
    rate_bps: np.ndarray
    planned_rate_bps: np.ndarray | None  # where avoiding with a planned point, else NaN
    avoiding: np.ndarray

    def rows(self) -> list[ServiceRow]:
        """``service.csv`` rows ``(t, user, power_w, sinr_db, rate_bps)``, sample-major."""
        n, k = self.rate_bps.shape
        return [
            (
                float(self.t[i]),
                j,
                float(self.power_w[i, j]),
                float(self.sinr_db[i, j]),
                float(self.rate_bps[i, j]),
            )
            for i in range(n)
            for j in range(k)
        ]


class Delivery:
    """Accumulates the service delivered over a mission, one sample (or a batch) at a time.

    ``power_w`` ``(K,)`` is the allocation in force; change it on a re-plan with
    :meth:`set_power` or per call with ``sample(..., power_w=...)``. ``qos_rate_bps`` defaults to
    the channel's. ``rng`` draws the fading (``fading: none`` draws nothing).
    """

    def __init__(
        self,
        channel: Channel,
        power_w: np.ndarray,
        qos_rate_bps: float | None = None,
        rng: np.random.Generator | None = None,
    ) -> None:
        self.channel = channel
        self.qos_rate_bps = float(channel.qos_rate_bps if qos_rate_bps is None else qos_rate_bps)
        self.rng = np.random.default_rng() if rng is None else rng
        self.power_w = self._check_power(power_w)
        k = channel.k
        self._bits = np.zeros(k)
        self._qos_s = 0.0  # user-seconds at or above the QoS rate
        self._time_s = 0.0
        self._avoiding_s = 0.0
        self._planned_bits = 0.0  # what the planned orbit would have delivered while avoiding
        self._flown_bits = 0.0  # what was delivered over those same samples
        self._samples = 0
        self.last: ServiceSample | None = None

    def _check_power(self, power_w: Any) -> np.ndarray:
        p = np.asarray(power_w, dtype=float)
        if p.shape[-1:] != (self.channel.k,) or not np.all(np.isfinite(p)) or np.any(p < 0):
            raise UserError(
                f"power allocation must be {self.channel.k} finite powers >= 0 W (one per "
                f"user), got shape {p.shape}"
            )
        return p

    def set_power(self, power_w: np.ndarray) -> None:
        """The allocation for the samples that follow (a re-planned service point's)."""
        self.power_w = self._check_power(power_w)

    def sample(
        self,
        t: float | np.ndarray,
        uav_pos: np.ndarray,
        users_pos: np.ndarray,
        dt: float | np.ndarray,
        planned_pos: np.ndarray | None = None,
        avoiding: bool | np.ndarray = False,
        power_w: np.ndarray | None = None,
    ) -> list[ServiceRow]:
        """Serve from ``uav_pos`` for ``dt`` seconds and return the ``service.csv`` rows.

        One sample: ``t`` scalar, ``uav_pos (3,)``, ``users_pos (K, 3)``. A batch of N: ``t``
        ``(N,)``, ``uav_pos (N, 3)``, ``users_pos (N, K, 3)`` or ``(K, 3)``, ``dt``,
        ``avoiding`` scalars or ``(N,)``, ``planned_pos (N, 3)``. The arrays are in
        :attr:`last` (e.g. the current rates for the recording).
        """
        t_arr = np.atleast_1d(np.asarray(t, dtype=float))
        n = len(t_arr)
        k = self.channel.k
        uav = np.asarray(uav_pos, dtype=float).reshape(n, 3)
        dt_arr = np.broadcast_to(np.asarray(dt, dtype=float), (n,))
        if not (np.all(np.isfinite(dt_arr)) and np.all(dt_arr >= 0)):
            raise UserError(f"service sample dt must be finite and >= 0 s, got {dt}")
        avoid = np.broadcast_to(np.asarray(avoiding, dtype=bool), (n,))
        power = self.power_w if power_w is None else self._check_power(power_w)
        power = np.broadcast_to(power, (n, k))
        # One draw per sample, in time order, whatever else happens: the stream and hence
        # service.csv do not depend on avoidance or on batching. Shadowing (if drawn) is drawn
        # at the flown position and reused for the planned one: the two rates compared while
        # avoiding then differ by the geometry only.
        if self.channel.fading == "none":
            fading = None
        else:
            users_n = np.broadcast_to(user_positions(self.channel, users_pos), (n, k, 3))
            fading = np.stack(
                [self.channel.draw_channel(self.rng, uav[i], users_n[i]) for i in range(n)]
            )
        sinr, rate = rates_at(self.channel, uav, users_pos, power, fading)

        planned_rate = None
        if planned_pos is not None and avoid.any():
            planned = np.asarray(planned_pos, dtype=float).reshape(n, 3)
            users = np.asarray(users_pos, dtype=float)
            users_a = users[avoid] if users.ndim == 3 else users
            f_a = None if fading is None else fading[avoid]
            _, r_plan = rates_at(self.channel, planned[avoid], users_a, power[avoid], f_a)
            planned_rate = np.full((n, k), np.nan)
            planned_rate[avoid] = r_plan
            w = dt_arr[avoid, None]
            self._planned_bits += float((r_plan * w).sum())
            self._flown_bits += float((rate[avoid] * w).sum())

        self._bits += (rate * dt_arr[:, None]).sum(axis=0)
        self._qos_s += float(((rate >= self.qos_rate_bps) * dt_arr[:, None]).sum())
        self._time_s += float(dt_arr.sum())
        self._avoiding_s += float(dt_arr[avoid].sum())
        self._samples += n
        with np.errstate(divide="ignore"):
            sinr_db = 10.0 * np.log10(sinr)
        self.last = ServiceSample(
            t=t_arr,
            dt=np.array(dt_arr),
            power_w=np.array(power),
            sinr_db=sinr_db,
            rate_bps=rate,
            planned_rate_bps=planned_rate,
            avoiding=np.array(avoid),
        )
        return self.last.rows()

    # ------------------------------------------------------------------ results
    @property
    def delivered_bits_per_user(self) -> np.ndarray:
        return self._bits.copy()

    def summary(self) -> dict[str, Any]:
        """The mission's service fields (README's ``mission``), JSON-ready."""
        bits = self._bits
        total = float(bits.sum())
        jain = jain_fairness(bits)
        user_s = self._time_s * self.channel.k
        return {
            "delivered_bits": total,
            "delivered_bits_per_user": [float(b) for b in bits],
            "qos_user_seconds_share": self._qos_s / user_s if user_s > 0 else 0.0,
            "jain_fairness": jain,
            "avoidance_lost_bits": self._planned_bits - self._flown_bits,
            # context for the figures above
            "service_time_s": self._time_s,
            "avoiding_s": self._avoiding_s,
            "avoidance_planned_bits": self._planned_bits,
            "mean_sum_rate_bps": total / self._time_s if self._time_s > 0 else 0.0,
            "samples": self._samples,
        }
