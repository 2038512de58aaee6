"""An interacting-multiple-model (IMM) track (``surveillance.tracker: imm``): per intruder five
Kalman filters, flying straight and turning right or left at two fixed rates, mixed by the
probability of each manoeuvre (Blom and Bar-Shalom's IMM, Bar-Shalom, Li and Kirubarajan,
*Estimation with Applications to Tracking and Navigation*, 2001, section 11.6).

Why beside the coordinated-turn EKF (:mod:`uavxai.surveillance.tracker`): the EKF carries one
turn-rate estimate and linearises around it, so after a few silent seconds it reads any
position offset as a velocity error and claims a velocity it does not know (a track silent for
6 s while its aircraft turned at 12 deg/s claims 4.5 m/s of velocity sigma with a 90th-
percentile error of 22.6 m/s: ``benchmarks/studies/bench_tracker_gaps.py``; the IMM 5.2 m/s
and 5.8). Here each mode is a linear filter at a fixed turn rate, exact for its manoeuvre, and
the position report weighs the modes: the spread between them is in the covariance the planner
reads, and a turn that started while unseen is found by the mode that flew it. The turn rates
(``w`` and ``2 w``, ``w = TrackerConfig.imm_turn_rate``: the traffic's turn at half its bank
limit) and the time between manoeuvres (``imm_sojourn_s``) are properties of the traffic
(:meth:`TrackerConfig.for_traffic`).

State per mode ``[x, y, vx, vy, h, vh]`` (ENU m, m/s), the same white-acceleration process
noise as the EKF's; the combined belief has the probability-weighted turn rate.
"""

from __future__ import annotations

import math

import numpy as np

from uavxai.avoidance.types import Intruder
from uavxai.surveillance import tracker as ekf
from uavxai.surveillance.adsb import Report
from uavxai.surveillance.emitters import emitter_table

X, Y, VX, VY, H, VH = range(6)
DIM = 6
_OF_EKF = [ekf.X, ekf.Y, ekf.VX, ekf.VY, ekf.H, ekf.VH]  # this state in the EKF's layout


def _transition(w: float, T: float) -> np.ndarray:
    """The linear state transition of a constant turn at ``w`` rad/s (clockwise) over ``T``
    (the EKF's coordinated turn with its turn rate held)."""
    return ekf.ct_transition(w, T)[np.ix_(_OF_EKF, _OF_EKF)]


def _noise(T: float, cfg: ekf.TrackerConfig) -> np.ndarray:
    """The EKF's white-acceleration process noise, without its turn-rate walk."""
    return ekf.ct_process_noise(T, cfg)[np.ix_(_OF_EKF, _OF_EKF)]


class ImmTrack:
    """One intruder's IMM: per mode a mean and covariance at ``t`` (its last measurement),
    and the mode probabilities ``mu``. The same interface as the EKF's ``Track``."""

    def __init__(self, report: Report, cfg: ekf.TrackerConfig) -> None:
        self.id = report.id
        self.cfg = cfg
        self.emitter = report.emitter
        self.t = self.t_first = report.t_measured
        self.updates = 1
        w = cfg.imm_turn_rate  # straight; right and left at w and 2 w (positive: right)
        self.rates = np.array([0.0, w, -w, 2.0 * w, -2.0 * w])
        m = len(self.rates)
        x7, var7 = ekf.initial_state(report, cfg)  # the EKF's first belief, less its turn rate
        x, var = x7[_OF_EKF], var7[_OF_EKF]
        self.x = np.repeat(x[None, :], m, axis=0)
        self.P = np.repeat(np.diag(var)[None, :, :], m, axis=0)
        self.mu = np.full(m, 0.4 / (m - 1))
        self.mu[0] = 0.6  # a new track most likely flies straight

    def _switch(self, T: float) -> np.ndarray:
        """Mode transition probabilities over ``T`` s: leave a mode at rate 1 / sojourn,
        to any other mode alike."""
        m = len(self.rates)
        leave = 1.0 - math.exp(-T / self.cfg.imm_sojourn_s)
        pi = np.full((m, m), leave / (m - 1))
        np.fill_diagonal(pi, 1.0 - leave)
        return pi

    def _predict_modes(self, T: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Mixed and predicted (means, covariances, prior mode probabilities) at t + T."""
        pi = self._switch(T)
        prior = self.mu @ pi  # P(mode j after T)
        mix = (self.mu[:, None] * pi) / np.maximum(prior[None, :], 1e-300)  # P(i | j)
        Q = _noise(T, self.cfg)
        xs, Ps = np.empty_like(self.x), np.empty_like(self.P)
        for j in range(len(self.rates)):
            x0 = mix[:, j] @ self.x
            d = self.x - x0
            P0 = np.einsum("i,ijk->jk", mix[:, j], self.P + d[:, :, None] * d[:, None, :])
            F = _transition(self.rates[j], T)
            xs[j], Ps[j] = F @ x0, F @ P0 @ F.T + Q
        return xs, Ps, prior

    def predicted(self, t: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(combined mean, combined covariance, mode probabilities) at ``t`` >= the track's
        time, without changing the track."""
        T = t - self.t
        xs, Ps, mu = (self.x, self.P, self.mu) if T <= 0 else self._predict_modes(T)
        x = mu @ xs
        d = xs - x
        P = np.einsum("i,ijk->jk", mu, Ps + d[:, :, None] * d[:, None, :])
        return x, P, mu

    def update(self, report: Report) -> bool:
        """Fold in a report measured at or after the track's time; False (ignored) if it is
        older."""
        if report.t_measured < self.t - 1e-9:
            return False
        xs, Ps, prior = self._predict_modes(max(report.t_measured - self.t, 0.0))
        sh, sv = report.sigma_pos
        if report.vel is not None and math.isfinite(report.sigma_vel[0]):
            idx = [X, Y, H, VX, VY, VH]
            z = np.concatenate([report.pos, report.vel])
            vh_, vv_ = report.sigma_vel
            r = np.array([sh, sh, sv, vh_, vh_, vv_]) ** 2
        else:
            idx, z, r = [X, Y, H], np.asarray(report.pos, dtype=float), np.array([sh, sh, sv]) ** 2
        R = np.diag(r + 1e-6)
        like = np.empty(len(self.rates))
        for j in range(len(self.rates)):
            S = Ps[j][np.ix_(idx, idx)] + R
            nu = z - xs[j][idx]
            K = np.linalg.solve(S, Ps[j][idx, :]).T
            A = np.eye(DIM)
            A[:, idx] -= K
            xs[j] = xs[j] + K @ nu
            Ps[j] = A @ Ps[j] @ A.T + K @ R @ K.T
            Ps[j] = 0.5 * (Ps[j] + Ps[j].T)
            _, logdet = np.linalg.slogdet(S)
            like[j] = -0.5 * (nu @ np.linalg.solve(S, nu) + logdet)
        post = prior * np.exp(like - like.max())
        self.mu = np.maximum(post / post.sum(), 1e-6)
        self.mu /= self.mu.sum()
        self.x, self.P, self.t = xs, Ps, report.t_measured
        self.emitter = report.emitter or self.emitter  # a sensor report carries none
        self.updates += 1
        return True

    def belief(self, t: float) -> Intruder:
        x, P, mu = self.predicted(t)
        return Intruder(
            id=self.id, x=float(x[X]), y=float(x[Y]), h=float(x[H]),
            vx=float(x[VX]), vy=float(x[VY]), vh=float(x[VH]),
            turn_rate=float(mu @ self.rates),
            sigma_m=ekf.largest_sd(P, X, Y), sigma_v=ekf.largest_sd(P, VX, VY),
            age_s=float(max(t - self.t, 0.0)),
            bank_limit_deg=emitter_table().bank_limit(self.emitter),
            sigma_h_m=float(np.sqrt(max(P[H, H], 0.0))),
            sigma_vh=float(np.sqrt(max(P[VH, VH], 0.0))),
        )  # fmt: skip
