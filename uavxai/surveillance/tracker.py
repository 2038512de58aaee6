"""Tracking: per intruder an extended Kalman filter on a coordinated-turn (CT) model, turning
surveillance reports into beliefs with uncertainty.

State ``[x, y, vx, vy, omega, h, vh]`` (ENU m, m/s; ``omega`` the turn rate of the ground
track in rad/s, positive clockwise, i.e. turning right, as headings are clockwise from north).
Horizontally the target flies a circle at constant speed and turn rate (exact discrete
propagation, the straight line being the omega -> 0 limit); vertically a constant climb rate.
Process noise: white acceleration on each axis (``accel_sigma_mps2``), a random walk of the
turn rate (``turn_rate_sigma``), white vertical acceleration. Measurements are linear (position,
and velocity when the report has one), so only the prediction is linearised, with the
Jacobian's turn-rate column taken by central differences.

A track is updated at each report's *measurement* time (so the latency is accounted for) and
predicted to the time asked for when beliefs are read: tracks without fresh reports coast,
their covariance growing, and are dropped once their last measurement is older than
``max_age_s``. The answer is a list of :class:`uavxai.avoidance.types.Intruder` with
``turn_rate``, ``sigma_m``, ``sigma_v`` and ``age_s`` filled in, and ``bank_limit_deg`` by the
emitter category the track's ADS-B reports carry (:mod:`uavxai.surveillance.emitters`; None for
a sensor-only track, which has none).

In wind the filter runs in the frame of the air mass (``Tracker(wind_mps=...)``, the steady
wind of ``environment.wind``): an aircraft turns at a constant rate through the air, so its
air-relative velocity rotates uniformly while its ground track is a trochoid that no
constant-turn model over the ground fits. Reports are moved into the air mass (position less
the wind's drift since t = 0, velocity less the wind) and beliefs back (the drift and the wind
added), so beliefs are over the ground as before, with ``turn_rate`` the air-relative one
(the aircraft's heading rate, g tan(bank) / airspeed); the planner's model predicts the same
way (:func:`uavxai.geometry.turn_positions` with its wind).

Why not filterpy: its EKF class would only hold the same matrices, its IMM works on linear
filters, and the whole filter is a few numpy lines here.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, replace

import numpy as np

from uavxai.avoidance.types import Intruder
from uavxai.dynamics.behaviours import TURN_HOLD_S
from uavxai.dynamics.state import TrafficState
from uavxai.errors import UserError
from uavxai.geometry import turn_rate_of_bank
from uavxai.scenario import Scenario
from uavxai.surveillance.adsb import Report
from uavxai.surveillance.emitters import TrafficCategories, emitter_table

X, Y, VX, VY, W, H, VH = range(7)
DIM = 7


@dataclass(frozen=True)
class TrackerConfig:
    accel_sigma_mps2: float = 1.0  # horizontal white acceleration, per axis, m/s^2
    turn_rate_sigma: float = 0.05  # turn-rate random walk, rad/s per sqrt(s) (tuned: see tests)
    vertical_accel_sigma_mps2: float = 0.3
    max_age_s: float = 6.0  # a track whose last measurement is older is dropped
    init_turn_rate_sigma: float = 0.2  # rad/s, a new track's turn-rate uncertainty
    init_vel_sigma_mps: float = 15.0  # velocity uncertainty of a track born position-only
    max_turn_rate: float = 1.0  # rad/s, the estimate is clipped to +- this
    # surveillance.tracker: imm (uavxai.surveillance.imm): the turn rate of its turning modes,
    # rad/s, and the mean time between manoeuvres, s (the traffic's; sim.picture sets them)
    imm_turn_rate: float = 0.12
    imm_sojourn_s: float = 12.5

    def __post_init__(self) -> None:
        for name in (
            "accel_sigma_mps2",
            "turn_rate_sigma",
            "vertical_accel_sigma_mps2",
            "max_age_s",
            "init_turn_rate_sigma",
            "init_vel_sigma_mps",
            "max_turn_rate",
            "imm_turn_rate",
            "imm_sojourn_s",
        ):
            if not getattr(self, name) > 0:
                raise UserError(f"TrackerConfig.{name} must be > 0, got {getattr(self, name)}")

    @classmethod
    def for_traffic(cls, scenario: Scenario) -> TrackerConfig:
        """The IMM's manoeuvres from the scenario's traffic: a turn at half its bank limit at
        its mean speed, and the random-turn pilots' mean hold between bank changes."""
        speed = 0.5 * sum(scenario.intruders.speed_mps)
        bank = 0.5 * math.radians(scenario.avoidance.bank_limit_deg)
        return cls(imm_turn_rate=turn_rate_of_bank(bank, speed),
                   imm_sojourn_s=0.5 * sum(TURN_HOLD_S))  # fmt: skip


def _ct_terms(w: float, T: float) -> tuple[float, float, float, float]:
    """sin(wT)/w, (1 - cos(wT))/w, cos(wT), sin(wT), with their w -> 0 limits."""
    a = w * T
    if abs(a) < 1e-4:
        s_over = T * (1.0 - a * a / 6.0)
        c_over = 0.5 * a * T * (1.0 - a * a / 12.0)
    else:
        s_over = math.sin(a) / w
        c_over = (1.0 - math.cos(a)) / w
    return s_over, c_over, math.cos(a), math.sin(a)


def ct_predict_state(x: np.ndarray, T: float) -> np.ndarray:
    """The CT model's state after ``T`` seconds (no noise)."""
    vx, vy, w = x[VX], x[VY], x[W]
    so, co, c, s = _ct_terms(w, T)
    out = x.copy()
    # heading rate w clockwise: d(vx)/dt = w vy, d(vy)/dt = -w vx
    out[X] = x[X] + vx * so + vy * co
    out[Y] = x[Y] - vx * co + vy * so
    out[VX] = vx * c + vy * s
    out[VY] = -vx * s + vy * c
    out[H] = x[H] + x[VH] * T
    return out


def ct_transition(w: float, T: float) -> np.ndarray:
    """The CT model's transition over ``T`` with the turn rate ``w`` held (linear in the rest
    of the state); the turn rate's own column is the identity's."""
    so, co, c, s = _ct_terms(w, T)
    F = np.eye(DIM)
    F[X, VX], F[X, VY] = so, co
    F[Y, VX], F[Y, VY] = -co, so
    F[VX, VX], F[VX, VY] = c, s
    F[VY, VX], F[VY, VY] = -s, c
    F[H, VH] = T
    return F


def ct_jacobian(x: np.ndarray, T: float) -> np.ndarray:
    """The CT model's Jacobian at ``x``: its transition, and the turn rate's column by central
    differences of the prediction."""
    F = ct_transition(x[W], T)
    eps = 1e-6
    xp, xm = x.copy(), x.copy()
    xp[W] += eps
    xm[W] -= eps
    F[:, W] = (ct_predict_state(xp, T) - ct_predict_state(xm, T)) / (2 * eps)
    F[W, W] = 1.0
    return F


def ct_process_noise(T: float, cfg: TrackerConfig) -> np.ndarray:
    """Discrete white-noise acceleration on (x, vx), (y, vy), (h, vh) and a turn-rate walk."""
    Q = np.zeros((DIM, DIM))
    a, b, c = T**3 / 3.0, T**2 / 2.0, T
    for p, v, sig in (
        (X, VX, cfg.accel_sigma_mps2),
        (Y, VY, cfg.accel_sigma_mps2),
        (H, VH, cfg.vertical_accel_sigma_mps2),
    ):
        q = sig * sig
        Q[p, p], Q[p, v], Q[v, p], Q[v, v] = a * q, b * q, b * q, c * q
    Q[W, W] = cfg.turn_rate_sigma**2 * T
    return Q


def largest_sd(P: np.ndarray, i: int, j: int) -> float:
    """Square root of the larger eigenvalue of the 2x2 block (i, j) of P (closed form)."""
    a, b, d = P[i, i], P[i, j], P[j, j]
    lam = 0.5 * (a + d) + math.sqrt(max(0.25 * (a - d) ** 2 + b * b, 0.0))
    return math.sqrt(max(lam, 0.0))


def initial_state(report: Report, cfg: TrackerConfig) -> tuple[np.ndarray, np.ndarray]:
    """A new track's mean and variances (this module's state layout) from its first report:
    the report's position and velocity with their errors, or a velocity unknown to
    ``init_vel_sigma_mps`` for a position-only report."""
    sh, sv = report.sigma_pos
    x = np.zeros(DIM)
    x[X], x[Y], x[H] = report.pos
    var = np.zeros(DIM)
    var[X] = var[Y] = sh**2 + 1e-6
    var[H] = sv**2 + 1e-6
    if report.vel is not None and math.isfinite(report.sigma_vel[0]):
        x[VX], x[VY], x[VH] = report.vel
        vh_, vv_ = report.sigma_vel
        var[VX] = var[VY] = vh_**2 + 1e-6
        var[VH] = vv_**2 + 1e-6
    else:
        var[VX] = var[VY] = cfg.init_vel_sigma_mps**2
        var[VH] = (cfg.init_vel_sigma_mps / 5.0) ** 2
    var[W] = cfg.init_turn_rate_sigma**2
    return x, var


class Track:
    """One intruder's filter: mean ``x`` and covariance ``P`` at time ``t`` (its last
    measurement); ``emitter`` the category its reports carry (None: none yet)."""

    def __init__(self, report: Report, cfg: TrackerConfig) -> None:
        self.id = report.id
        self.cfg = cfg
        self.emitter = report.emitter
        self.t = report.t_measured
        self.t_first = report.t_measured
        self.updates = 1
        x, var = initial_state(report, cfg)
        self.x = x
        self.P = np.diag(var)

    def predicted(self, t: float) -> tuple[np.ndarray, np.ndarray]:
        """(mean, covariance) at ``t`` >= the track's time, without changing the track."""
        T = t - self.t
        if T <= 0:
            return self.x.copy(), self.P.copy()
        F = ct_jacobian(self.x, T)
        x = ct_predict_state(self.x, T)
        P = F @ self.P @ F.T + ct_process_noise(T, self.cfg)
        return x, P

    def update(self, report: Report) -> bool:
        """Fold in a report measured at or after the track's time; False (ignored) if it is
        older."""
        if report.t_measured < self.t - 1e-9:
            return False
        x, P = self.predicted(report.t_measured)
        sh, sv = report.sigma_pos
        has_vel = report.vel is not None and math.isfinite(report.sigma_vel[0])
        if has_vel:
            idx = [X, Y, H, VX, VY, VH]
            z = np.concatenate([report.pos, report.vel])  # type: ignore[list-item]
            vh_, vv_ = report.sigma_vel
            r = np.array([sh, sh, sv, vh_, vh_, vv_]) ** 2
        else:
            idx = [X, Y, H]
            z = np.asarray(report.pos, dtype=float)
            r = np.array([sh, sh, sv]) ** 2
        r = r + 1e-6  # exact (truth) reports: keep the innovation covariance invertible
        Hm = np.zeros((len(idx), DIM))
        Hm[np.arange(len(idx)), idx] = 1.0
        S = Hm @ P @ Hm.T + np.diag(r)
        K = np.linalg.solve(S, Hm @ P).T  # P H^T S^-1 (S symmetric)
        x = x + K @ (z - x[idx])
        # Joseph form: stays symmetric positive definite
        A = np.eye(DIM) - K @ Hm
        P = A @ P @ A.T + K @ np.diag(r) @ K.T
        lim = self.cfg.max_turn_rate
        x[W] = min(max(x[W], -lim), lim)
        self.x, self.P, self.t = x, 0.5 * (P + P.T), report.t_measured
        self.emitter = report.emitter or self.emitter  # a sensor report carries none
        self.updates += 1
        return True

    def belief(self, t: float) -> Intruder:
        x, P = self.predicted(t)
        return Intruder(
            id=self.id,
            x=float(x[X]),
            y=float(x[Y]),
            h=float(x[H]),
            vx=float(x[VX]),
            vy=float(x[VY]),
            vh=float(x[VH]),
            turn_rate=float(x[W]),
            # the larger axis of the horizontal error ellipse: conservative for separation
            sigma_m=largest_sd(P, X, Y),
            sigma_v=largest_sd(P, VX, VY),
            age_s=float(max(t - self.t, 0.0)),
            bank_limit_deg=emitter_table().bank_limit(self.emitter),
            sigma_h_m=float(np.sqrt(max(P[H, H], 0.0))),
            sigma_vh=float(np.sqrt(max(P[VH, VH], 0.0))),
        )


class Tracker:
    """All tracks, by intruder id; ``wind_mps`` (east, north): the steady wind, tracked in
    the air mass's frame (module docstring); ``track``: the filter of one track."""

    def __init__(
        self,
        config: TrackerConfig | None = None,
        wind_mps: tuple[float, float] = (0.0, 0.0),
        track: type = Track,
    ) -> None:
        self.config = config or TrackerConfig()
        self._new_track = track  # Track (the EKF) or uavxai.surveillance.imm.ImmTrack
        self.wind = np.array([float(wind_mps[0]), float(wind_mps[1]), 0.0])
        self._windy = bool(np.any(self.wind))
        self.tracks: dict[str, Track] = {}
        self.ignored = 0  # reports older than their track (out of order)
        self.dropped: list[str] = []  # ids of tracks dropped as stale, in order

    def update(self, reports: Iterable[Report]) -> None:
        for r in sorted(reports, key=lambda r: r.t_measured):
            if self._windy:
                r = self._into_air(r)
            track = self.tracks.get(r.id)
            if track is None:
                self.tracks[r.id] = self._new_track(r, self.config)
            elif not track.update(r):
                self.ignored += 1

    def prune(self, t: float) -> None:
        """Drop tracks whose last measurement is older than ``max_age_s`` at ``t``."""
        for ident in [i for i, tr in self.tracks.items() if t - tr.t > self.config.max_age_s]:
            del self.tracks[ident]
            self.dropped.append(ident)

    def beliefs(self, t: float) -> list[Intruder]:
        """Every live track predicted to ``t`` (stale ones are dropped first), in id order
        of first appearance."""
        self.prune(t)
        beliefs = [tr.belief(t) for tr in self.tracks.values()]
        return [self._over_ground(b, t) for b in beliefs] if self._windy else beliefs

    def _into_air(self, r: Report) -> Report:
        """A report moved into the air mass: where it was less the drift since t = 0."""
        vel = None if r.vel is None else np.asarray(r.vel, dtype=float) - self.wind
        return replace(r, pos=np.asarray(r.pos, dtype=float) - self.wind * r.t_measured, vel=vel)

    def _over_ground(self, b: Intruder, t: float) -> Intruder:
        """A belief in the air mass back over the ground at ``t``."""
        we, wn = float(self.wind[0]), float(self.wind[1])
        return replace(b, x=b.x + we * t, y=b.y + wn * t, vx=b.vx + we, vy=b.vy + wn)


def truth_beliefs(
    state: TrafficState, categories: TrafficCategories | None = None
) -> list[Intruder]:
    """Every intruder's exact state (``surveillance.model: truth``), with the turn rate of
    its coordinated turn, g tan(phi) / V (true airspeed), and no uncertainty; with the
    episode's ``categories`` the bank limit of each one's category too (None: the planner's
    default for every one)."""
    out = []
    for i in range(1, state.n):
        v = max(float(state.airspeed[i]), 1.0)
        out.append(
            Intruder(
                id=state.ids[i],
                x=float(state.pos[i, 0]),
                y=float(state.pos[i, 1]),
                h=float(state.pos[i, 2]),
                vx=float(state.vel[i, 0]),
                vy=float(state.vel[i, 1]),
                vh=float(state.vel[i, 2]),
                turn_rate=turn_rate_of_bank(float(state.att[i, 0]), v),
                bank_limit_deg=None if categories is None else categories.bank_limit_deg(
                    state.ids[i]
                ),
            )
        )
    return out
