"""The `track` pilot: an intruder that follows a given trajectory (an encounter-model track).

The track is any object with the arrays of :class:`uavxai.encounters.tracks.Trajectory`
(``t, x, y, h, vx, vy, vh``: s, m, m/s in the local ENU frame; duck-typed, because
``uavxai.dynamics`` and ``uavxai.encounters`` are independent layers). Track time 0 is world
time ``t0``; before it the track's first sample is aimed at, after its end the last sample
is extrapolated along its velocity.

The law, evaluated every pilot period (``PILOT_PERIOD_S``, 1 s), with ``p`` the track's point
at the current time, ``chi_p`` its course, ``omega`` its turn rate (the heading change over the
next period), ``V`` the aircraft's ground speed and ``chi`` its ground course:

* **bank** = atan(V omega / g) (the coordinated turn that gives the track's turn rate at the
  speed actually flown) + atan(V K_chi wrap(chi_d - chi) / g), where the desired course
  chi_d = chi_p - atan(e_ct / L) turns towards the track from the cross-track error e_ct
  (positive: right of it) over the look-ahead L = V x ``LOOKAHEAD_S``, and
  K_chi = 1 / ``COURSE_TIME_S``; the sum is clipped to the bank limit.
* **speed target** = the track's speed + ``ALONG_GAIN`` x the along-track error (positive:
  the track point is ahead), the correction clipped to +-``ALONG_MAX_MPS`` and the result to
  the aircraft's speed range.
* **altitude target** = h_p + vh_p / k_h, with k_h the autopilot's height gain (height error
  to climb-rate demand, 0.2 /s for ga_c172, 0.25 /s for uav_fw): the autopilot's climb-rate
  demand k_h (target - h) is then the track's vertical rate plus k_h times the height error,
  i.e. a vertical-rate feed-forward with a proportional correction, through the altitude
  interface every autopilot of ours has. The autopilot's climb-rate limit still applies.

The kinematic world flies the height target the same way (its intruders climb at their
autopilot's gain, clipped to its climb-rate limit: uavxai.sim.kinematic.height_step).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Protocol

import numpy as np

from uavxai.geometry import bank_of_turn_rate, wrap_angle

LOOKAHEAD_S = 8.0  # cross-track error turned into a course error over V x this
COURSE_TIME_S = 4.0  # a course error is corrected with this time constant
ALONG_GAIN = 0.05  # speed target per metre of along-track error, 1/s
ALONG_MAX_MPS = 5.0


class TrackLike(Protocol):
    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    h: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    vh: np.ndarray


class TrackPilot:
    """Follows ``track`` from world time ``t0``; ``command`` as :class:`IntruderPilot`'s,
    plus :meth:`alt_target`. ``offset`` (x, y, h) shifts the whole track."""

    behaviour = "track"

    def __init__(
        self,
        track: TrackLike,
        bank_limit_rad: float,
        speed_range: tuple[float, float] = (0.0, math.inf),
        t0: float = 0.0,
        offset: Sequence[float] = (0.0, 0.0, 0.0),
        height_gain_per_s: float = 0.2,
        period_s: float = 1.0,
    ) -> None:
        t = np.asarray(track.t, dtype=float)
        if t.ndim != 1 or len(t) < 2 or not np.all(np.diff(t) > 0):
            raise ValueError("a track needs at least two samples at increasing times")
        if height_gain_per_s <= 0 or period_s <= 0:
            raise ValueError("height_gain_per_s and period_s must be > 0")
        ox, oy, oh = (float(v) for v in offset)
        self._t = t
        self._x = np.asarray(track.x, dtype=float) + ox
        self._y = np.asarray(track.y, dtype=float) + oy
        self._h = np.asarray(track.h, dtype=float) + oh
        self._vx = np.asarray(track.vx, dtype=float)
        self._vy = np.asarray(track.vy, dtype=float)
        self._vh = np.asarray(track.vh, dtype=float)
        self._psi = np.unwrap(np.arctan2(self._vx, self._vy))
        self.t0 = float(t0)
        self.bank_limit_rad = float(bank_limit_rad)
        self.speed_range = (float(speed_range[0]), float(speed_range[1]))
        self.height_gain = float(height_gain_per_s)
        self.period_s = float(period_s)
        self.speed_mps = float(np.hypot(self._vx[0], self._vy[0]))

    # --------------------------------------------------------------------------- the track
    def point(self, t: float) -> tuple[np.ndarray, np.ndarray, float]:
        """The track at world time ``t``: position (x, y, h), velocity (vx, vy, vh), heading
        (rad, unwrapped). Held at the first sample before the start, extrapolated along the
        last velocity after the end."""
        tau = t - self.t0
        tt = self._t
        if tau <= tt[0]:
            i = 0
            pos = np.array([self._x[0], self._y[0], self._h[0]])
        elif tau >= tt[-1]:
            i = len(tt) - 1
            dt = tau - tt[-1]
            pos = np.array(
                [self._x[i] + self._vx[i] * dt, self._y[i] + self._vy[i] * dt,
                 self._h[i] + self._vh[i] * dt]
            )
        else:
            pos = np.array([np.interp(tau, tt, a) for a in (self._x, self._y, self._h)])
            i = -1
        if i >= 0:
            vel = np.array([self._vx[i], self._vy[i], self._vh[i]])
            psi = float(self._psi[i])
        else:
            vel = np.array([np.interp(tau, tt, a) for a in (self._vx, self._vy, self._vh)])
            psi = float(np.interp(tau, tt, self._psi))
        return pos, vel, psi

    def turn_rate(self, t: float) -> float:
        """The track's heading rate over the next pilot period (rad/s, clockwise positive)."""
        tau = t - self.t0
        a, b = tau, tau + self.period_s
        lo, hi = self._t[0], self._t[-1]
        a, b = min(max(a, lo), hi), min(max(b, lo), hi)
        if b - a < 1e-9:
            return 0.0
        return float(np.interp(b, self._t, self._psi) - np.interp(a, self._t, self._psi)) / (b - a)

    # ---------------------------------------------------------------------------- the law
    def command(
        self, t: float, pos: Sequence[float], vel: Sequence[float], psi: float
    ) -> tuple[float, float]:
        """(bank_cmd_rad, speed_target_mps) for an aircraft at ``pos`` with ground velocity
        ``vel`` at world time ``t`` (the module's law)."""
        p, v, psi_p = self.point(t)
        ground = math.hypot(vel[0], vel[1])
        speed = max(ground, 1.0)
        chi = math.atan2(vel[0], vel[1]) if ground > 1.0 else psi
        # errors in the track's frame: along its course, and to its right
        dx, dy = pos[0] - p[0], pos[1] - p[1]
        s, c = math.sin(psi_p), math.cos(psi_p)
        along = -(dx * s + dy * c)  # > 0: the track point is ahead of the aircraft
        cross = dx * c - dy * s  # > 0: the aircraft is right of the track
        omega = self.turn_rate(t)
        bank_ff = bank_of_turn_rate(omega, speed)
        chi_d = psi_p - math.atan(cross / (speed * LOOKAHEAD_S))
        bank_fb = bank_of_turn_rate(wrap_angle(chi_d - chi) / COURSE_TIME_S, speed)
        lim = self.bank_limit_rad
        bank = min(max(bank_ff + bank_fb, -lim), lim)
        track_speed = math.hypot(v[0], v[1])
        correction = min(max(ALONG_GAIN * along, -ALONG_MAX_MPS), ALONG_MAX_MPS)
        lo, hi = self.speed_range
        return bank, min(max(track_speed + correction, lo), hi)

    def alt_target(self, t: float) -> float:
        """The height target at world time ``t``: h_p + vh_p / k_h (the module's law)."""
        p, v, _ = self.point(t)
        return float(p[2] + v[2] / self.height_gain)
