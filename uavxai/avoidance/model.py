"""The encounter model: how the ownship flies one action, and whether that meets anything.

Every planner (and the kinematic episode runner) predicts with this one model, so a tree
search, its exhaustive reference and the campaign's "ground truth" agree on physics.

Ownship (vectorised over a batch of states): the action changes the bank *command* by one
``bank_step`` (clamped to the bank limit); the actual bank follows it at the autopilot's
roll-rate limit; the turn is coordinated, ``psi_dot = g tan(phi) / V``; the speed changes at
the commanded acceleration within the speed limits; the altitude moves towards the goal's
altitude (the target the JSBSim autopilot holds) at a bounded climb rate. Everything is in
closed form over a grid of sub-steps, so a segment costs a fixed number of numpy calls.

Intruders are given as a :class:`Track`: their positions at the segment's sub-step instants
(constant velocity when predicted). Collision is a 3-D separation below ``d_min`` at *any*
instant: within one sub-step both aircraft move on straight lines (the ownship on the exact
chord of its arc), so the closest approach on every sub-step is solved in closed form and a
pass-through between samples is caught.

Speed (a tree search calls this hundreds of times per decision): the ownship's motion relative
to its start, in its own body frame, depends only on (speed, bank, bank command) and the
action, so :meth:`EncounterModel.fly_all_actions` memoises it; and intruders, the goal and
walls that cannot be reached within the segment are skipped before the closed-form checks.
Both are exact: they change the cost, never the answer.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uavxai.avoidance.types import ACCEL_CHOICES, BANK_CHOICES, N_ACTIONS, Ownship, PlannerConfig

G = 9.80665  # m/s^2

# Columns of a state row.
X, Y, H, V, PSI, PHI, PHI_CMD = range(7)
STATE_DIM = 7

# Terminal codes (SearchTree.terminal uses the same numbers).
NONE, GOAL, COLLISION, OUT_OF_BOUNDS, TIMEOUT = 0, 1, 2, 3, 4
OUTCOME_NAMES = ("", "goal", "collision", "out_of_bounds", "timeout")
# Paper eqs 13/14: goal 1, collision 0, time-out 0.1; leaving the map counts as a failure (0).
TERMINAL_VALUE = (math.nan, 1.0, 0.0, 0.0, 0.1)

ALL_ACTIONS = np.arange(N_ACTIONS)
_BANK_SIGN = np.repeat(np.array(BANK_CHOICES, dtype=float), 3)  # by action index
_ACCEL_SIGN = np.tile(np.array(ACCEL_CHOICES, dtype=float), 3)
_EVENT_CODES = np.array([COLLISION, OUT_OF_BOUNDS, GOAL], dtype=np.int8)


def ownship_state(own: Ownship) -> np.ndarray:
    """One state row from the planner-API ownship."""
    phi = own.bank if own.phi is None else own.phi
    return np.array([own.x, own.y, own.h, own.speed, own.heading, phi, own.bank], dtype=float)


def state_to_ownship(state: np.ndarray) -> Ownship:
    return Ownship(
        x=float(state[X]),
        y=float(state[Y]),
        h=float(state[H]),
        speed=float(state[V]),
        heading=float(state[PSI]),
        bank=float(state[PHI_CMD]),
        phi=float(state[PHI]),
    )


def bank_command(current_cmd, action, cfg: PlannerConfig):
    """The bank command after ``action``: one step left/right of the current one, clamped."""
    lim = cfg.bank_limit_rad
    return np.clip(current_cmd + _BANK_SIGN[action] * cfg.bank_step_rad, -lim, lim)


def accel_command(action, cfg: PlannerConfig):
    return _ACCEL_SIGN[action] * cfg.accel_mps2


@dataclass(frozen=True)
class Track:
    """Intruder positions at a segment's sub-step instants, and a ball bounding each path.

    Between two instants an intruder moves in a straight line, so the ball around its samples
    holds its whole path: an ownship that cannot get within ``d_min`` of the ball is safe from
    it for the segment.
    """

    pos: np.ndarray  # (n+1, N, 3)
    centre: np.ndarray  # (N, 3)
    radius: np.ndarray  # (N,)

    @classmethod
    def of(cls, pos: np.ndarray) -> Track:
        if pos.ndim != 3 or pos.shape[2] != 3:
            raise ValueError(f"intruder positions must be (n+1, N, 3), got {pos.shape}")
        centre = 0.5 * (pos.min(axis=0) + pos.max(axis=0))
        radius = np.sqrt(np.max(np.sum((pos - centre) ** 2, axis=2), axis=0))
        return cls(pos, centre, radius)

    @property
    def n(self) -> int:
        """Number of sub-steps."""
        return self.pos.shape[0] - 1

    @property
    def count(self) -> int:
        return self.pos.shape[1]

    def near(self, point: np.ndarray, distance: float) -> np.ndarray:
        """Indices of intruders whose path may come within ``distance`` of ``point`` (3,)."""
        d2 = np.sum((self.centre - point) ** 2, axis=1)
        return np.flatnonzero(d2 <= (distance + self.radius) ** 2)

    def near_any(self, points: np.ndarray, distance: float) -> np.ndarray:
        """As :meth:`near`, for any of the ``points`` (B, 3)."""
        d2 = np.sum((self.centre[None] - points[:, None]) ** 2, axis=2).min(axis=0)
        return np.flatnonzero(d2 <= (distance + self.radius) ** 2)


@dataclass(frozen=True)
class Segment:
    """A batch of ownship states, each flying one action for the same duration.

    ``min_sep``, ``closest`` and ``t_closest`` count the segment only up to its event: after
    reaching the goal (or colliding) nothing more is flown. Intruders that cannot come within
    ``d_min`` are skipped unless the segment was flown with ``cull=False``, so a segment with
    none in reach reports ``min_sep`` inf and ``closest`` -1.
    """

    end: np.ndarray  # (B, 7) states at the end
    samples: np.ndarray | None  # (B, n+1, 3) positions at the sub-step instants (see fly_all)
    min_sep: np.ndarray  # (B,) smallest 3-D distance to an intruder, m
    closest: np.ndarray  # (B,) index of that intruder
    t_closest: np.ndarray  # (B,) seconds from the segment's start to that closest approach
    event: np.ndarray  # (B,) int8 terminal code, NONE when nothing happened
    t_event: np.ndarray  # (B,) seconds from the start to the start of the event's sub-step


@dataclass(frozen=True)
class _BodyMotion:
    """Motion relative to the start, in the start's body frame (forward, right)."""

    fwd: np.ndarray  # (B, n+1) m
    right: np.ndarray  # (B, n+1) m
    dpsi: np.ndarray  # (B,) heading change, rad
    v_end: np.ndarray  # (B,)
    phi_end: np.ndarray  # (B,)
    phi_cmd: np.ndarray  # (B,)


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


class EncounterModel:
    """Closed-loop ownship kinematics and intruder tracks (see the module docstring)."""

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config
        self._lo = np.array([config.x_bounds[0], config.y_bounds[0], config.h_bounds[0]])
        self._hi = np.array([config.x_bounds[1], config.y_bounds[1], config.h_bounds[1]])
        self._roll = math.radians(config.roll_rate_limit_deg_s)
        self._memo: dict[tuple[float, float, float, float], _BodyMotion] = {}
        # What a segment with nothing in reach reports, shared and read-only.
        self._quiet = (
            _frozen(np.full(N_ACTIONS, np.inf)),
            _frozen(np.full(N_ACTIONS, -1)),
            _frozen(np.zeros(N_ACTIONS)),
            _frozen(np.zeros(N_ACTIONS, dtype=np.int8)),
            _frozen(np.full(N_ACTIONS, np.nan)),
        )

    # ------------------------------------------------------------------------------- helpers
    def substeps(self, duration: float) -> int:
        """Sub-steps of a segment: the fewest of at most ``substep_s`` each."""
        return max(1, math.ceil(duration / self.config.substep_s - 1e-9))

    def predict(self, pos: np.ndarray, vel: np.ndarray, duration: float, t0: float = 0.0) -> Track:
        """Constant-velocity track over [t0, t0 + duration] of intruders now at ``pos``."""
        n = self.substeps(duration)
        t = t0 + (duration / n) * np.arange(n + 1)
        return Track.of(pos[None, :, :] + t[:, None, None] * vel[None, :, :])

    def leaf_value(self, positions: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Paper eq 13 for non-terminal states: 1 - d(o, g) / d_max."""
        d = np.sqrt(np.sum((positions[..., :3] - goal) ** 2, axis=-1))
        return 1.0 - d / self.config.d_max

    def reach(self, speed: float, duration: float) -> float:
        """How far (3-D) the ownship can get from its start within ``duration``."""
        v_top = max(self.config.speed_mps[1], speed)
        return math.hypot(v_top, self.config.climb_rate_mps) * duration

    # -------------------------------------------------------------------------------- flying
    def fly(
        self,
        states: np.ndarray,
        actions: np.ndarray,
        goal: np.ndarray,
        duration: float,
        track: Track,
        *,
        cull: bool = True,
    ) -> Segment:
        """Fly ``actions`` (B,) from ``states`` (B, 7) for ``duration`` seconds.

        ``track`` holds the intruders at this segment's sub-step instants (``predict`` makes
        it). ``cull=False`` measures the separation to every intruder, in reach or not.
        """
        cfg = self.config
        n = self._check(duration, track)
        body = self._body(states[:, V], states[:, PHI], states[:, PHI_CMD], actions, duration, n)
        x, y, h, psi = (states[:, k, None] for k in (X, Y, H, PSI))
        end = self._end(x, y, h, psi, body, goal[2], duration)
        samples = self._samples(x, y, h, psi, body, goal[2], duration, n)
        start = states[:, :3]
        reach = self.reach(float(states[:, V].max()), duration)
        near_goal = np.min(np.sum((start - goal) ** 2, axis=1)) <= (reach + cfg.goal_radius_m) ** 2
        climb = cfg.climb_rate_mps * duration
        span = np.array([reach, reach, climb])
        near_wall = bool(np.any(start - span < self._lo) or np.any(start + span > self._hi))
        near = track.near_any(start, reach + cfg.d_min_m) if cull else np.arange(track.count)
        return self._events(end, samples, goal, track, near, near_goal, near_wall, duration / n)

    def fly_all_actions(
        self, state: np.ndarray, goal: np.ndarray, duration: float, track: Track
    ) -> Segment:
        """The 9 children of one state, in action order: ``fly`` with every action, memoised.

        The answer equals ``fly``'s, except that ``samples`` is None when nothing (intruder,
        goal or wall) was within reach, since then no sample was needed.
        """
        cfg = self.config
        n = self._check(duration, track)
        x, y, h, v, psi, phi, cmd = state.tolist()
        # Keys are rounded far below any physical effect so that states reached along
        # different float paths (20 + 4 - 4) share an entry; the motion is computed from the
        # key itself, so the answer never depends on what the memo already holds.
        key = (round(v, 6), round(phi, 9), round(cmd, 9), float(duration))
        body = self._memo.get(key)
        if body is None:
            if len(self._memo) > 50_000:
                self._memo.clear()
            v_, phi_, cmd_ = (np.full(N_ACTIONS, k) for k in key[:3])
            body = self._memo[key] = self._body(v_, phi_, cmd_, ALL_ACTIONS, duration, n)
        end = self._end(x, y, h, psi, body, goal[2], duration)

        reach = self.reach(v, duration)
        climb = cfg.climb_rate_mps * duration
        near_goal = math.dist((x, y, h), goal) <= reach + cfg.goal_radius_m
        near_wall = not (
            cfg.x_bounds[0] <= x - reach
            and x + reach <= cfg.x_bounds[1]
            and cfg.y_bounds[0] <= y - reach
            and y + reach <= cfg.y_bounds[1]
            and cfg.h_bounds[0] <= h - climb
            and h + climb <= cfg.h_bounds[1]
        )
        near = track.near(state[:3], reach + cfg.d_min_m)
        if not (near.size or near_goal or near_wall):
            return Segment(end, None, *self._quiet)
        samples = self._samples(x, y, h, psi, body, goal[2], duration, n)
        return self._events(end, samples, goal, track, near, near_goal, near_wall, duration / n)

    def _check(self, duration: float, track: Track) -> int:
        n = self.substeps(duration)
        if track.n != n:
            raise ValueError(
                f"the intruder track has {track.n} sub-steps, a {duration} s segment has {n}"
            )
        return n

    def _body(self, v0, phi0, cmd0, actions, duration: float, n: int) -> _BodyMotion:
        cfg = self.config
        dt = duration / n
        tm = dt * (np.arange(n) + 0.5)  # sub-step midpoints
        roll = self._roll
        phi_cmd = bank_command(cmd0, actions, cfg)
        accel = accel_command(actions, cfg)
        vmin = np.minimum(cfg.speed_mps[0], v0)  # an out-of-range start speed never jumps
        vmax = np.maximum(cfg.speed_mps[1], v0)

        dphi = (phi_cmd - phi0)[:, None]
        phi_m = phi0[:, None] + np.clip(dphi, -roll * tm, roll * tm)
        v_m = np.clip(v0[:, None] + accel[:, None] * tm, vmin[:, None], vmax[:, None])
        # Coordinated turn: on each sub-step the rate is taken at its midpoint and the
        # displacement is the exact chord of that constant-rate arc.
        dpsi = G * np.tan(phi_m) / v_m * dt
        psi = np.cumsum(dpsi, axis=1)
        chord = v_m * dt * np.sinc(dpsi / (2.0 * np.pi))
        rel_heading = psi - 0.5 * dpsi  # mid-sub-step heading relative to the start
        fwd = np.zeros((len(v0), n + 1))
        right = np.zeros((len(v0), n + 1))
        np.cumsum(chord * np.cos(rel_heading), axis=1, out=fwd[:, 1:])
        np.cumsum(chord * np.sin(rel_heading), axis=1, out=right[:, 1:])

        # End values land exactly on the command / limit once reached, so lattice states
        # (and their memo keys) repeat.
        roll_reach = roll * duration
        phi_end = np.where(
            np.abs(dphi[:, 0]) <= roll_reach, phi_cmd, phi0 + np.sign(dphi[:, 0]) * roll_reach
        )
        v_end = np.clip(v0 + accel * duration, vmin, vmax)
        return _BodyMotion(fwd, right, psi[:, -1], v_end, phi_end, phi_cmd)

    # The start (x, y, h, psi) is either Python floats (one state for every row) or (B, 1)
    # arrays; the float case is the tree search's hot path, hence math rather than numpy.
    def _end(self, x, y, h, psi, body: _BodyMotion, goal_h: float, duration: float):
        climb = self.config.climb_rate_mps * duration
        f, r = body.fwd[:, -1], body.right[:, -1]
        end = np.empty((len(f), STATE_DIM))
        if isinstance(psi, float):
            s, c = math.sin(psi), math.cos(psi)
            end[:, H] = h + min(max(goal_h - h, -climb), climb)
        else:
            x, y, h, psi = x[:, 0], y[:, 0], h[:, 0], psi[:, 0]
            s, c = np.sin(psi), np.cos(psi)
            end[:, H] = h + np.clip(goal_h - h, -climb, climb)
        end[:, X] = x + f * s + r * c
        end[:, Y] = y + f * c - r * s
        end[:, V] = body.v_end
        end[:, PSI] = np.mod(psi + body.dpsi, 2.0 * np.pi)
        end[:, PHI] = body.phi_end
        end[:, PHI_CMD] = body.phi_cmd
        return end

    def _samples(self, x, y, h, psi, body: _BodyMotion, goal_h: float, duration: float, n: int):
        trig = math if isinstance(psi, float) else np
        s, c = trig.sin(psi), trig.cos(psi)
        samples = np.empty((len(body.fwd), n + 1, 3))
        samples[:, :, 0] = x + body.fwd * s + body.right * c
        samples[:, :, 1] = y + body.fwd * c - body.right * s
        climb = self.config.climb_rate_mps * (duration / n) * np.arange(n + 1)
        samples[:, :, 2] = h + np.clip(goal_h - h, -climb, climb)
        return samples

    # -------------------------------------------------------------------------------- events
    def _events(
        self,
        end: np.ndarray,
        samples: np.ndarray,
        goal: np.ndarray,
        track: Track,
        near: np.ndarray,
        near_goal: bool,
        near_wall: bool,
        dt: float,
    ) -> Segment:
        cfg = self.config
        B, n = samples.shape[0], samples.shape[1] - 1
        rows = np.arange(B)
        if near.size:
            d2, s = _closest_on_chords(samples[:, :, None, :] - track.pos[:, near][None])
            k = near.size
            flat = d2.reshape(B, n * k).argmin(axis=1)  # the closest approach: sub-step, who
            d2_min = d2.reshape(B, n * k)[rows, flat]
            k_min, j_min = np.divmod(flat, k)
            if not (near_goal or near_wall) and d2_min.min() >= cfg.d_min_m**2:
                # The common case: nothing happens, so the whole segment counts.
                quiet = self._quiet
                return Segment(
                    end=end,
                    samples=samples,
                    min_sep=np.sqrt(d2_min),
                    closest=near[j_min],
                    t_closest=(k_min + s[rows, k_min, j_min]) * dt,
                    event=quiet[3] if B == N_ACTIONS else np.zeros(B, dtype=np.int8),
                    t_event=quiet[4] if B == N_ACTIONS else np.full(B, np.nan),
                )
            d2_step = d2.min(axis=2)  # (B, n): closest intruder on each sub-step
            k_hit = _first_true(d2_step < cfg.d_min_m**2)
        else:
            k_hit = np.full(B, n)
        k_goal = k_out = np.full(B, n)
        if near_goal:
            g_d2, _ = _closest_on_chords(samples - goal)
            k_goal = _first_true(g_d2 < cfg.goal_radius_m**2)
        if near_wall:
            # The box is convex: a chord between two samples inside it stays inside.
            outside = (samples[:, 1:] < self._lo) | (samples[:, 1:] > self._hi)
            k_out = _first_true(np.any(outside, axis=2))

        # The first event wins; at equal sub-steps collision beats leaving the map beats the
        # goal (the conservative reading of a sub-step that holds two of them).
        first = np.stack([k_hit, k_out, k_goal])
        kind = np.argmin(first, axis=0)
        k_event = first[kind, rows]
        happened = k_event < n
        event = np.where(happened, _EVENT_CODES[kind], NONE).astype(np.int8)
        t_event = np.where(happened, k_event * dt, np.nan)
        if not near.size:
            inf = np.full(B, np.inf)
            return Segment(end, samples, inf, np.full(B, -1), np.zeros(B), event, t_event)

        # Separation counts only up to (and including) the event's sub-step.
        d2 = np.where((np.arange(n)[None, :] > k_event[:, None])[..., None], np.inf, d2)
        flat = d2.reshape(B, n * k).argmin(axis=1)
        k_min, j_min = np.divmod(flat, k)
        return Segment(
            end=end,
            samples=samples,
            min_sep=np.sqrt(d2[rows, k_min, j_min]),
            closest=near[j_min],
            t_closest=(k_min + s[rows, k_min, j_min]) * dt,
            event=event,
            t_event=t_event,
        )


def _closest_on_chords(rel: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Squared closest distance and its fraction ``s`` in [0, 1] on every sub-step.

    ``rel`` (B, n+1, [N,] 3) holds relative positions at the sub-step instants; along axis 1
    the relative motion is linear within each sub-step. Returns arrays of shape (B, n[, N]).
    """
    r0 = rel[:, :-1]
    dr = rel[:, 1:] - r0
    a = np.einsum("...i,...i->...", dr, dr)
    b = np.einsum("...i,...i->...", r0, dr)
    c = np.einsum("...i,...i->...", r0, r0)
    s = np.maximum(a, 1e-12)
    np.divide(b, s, out=s)
    np.negative(s, out=s)
    np.maximum(s, 0.0, out=s)
    np.minimum(s, 1.0, out=s)
    # |r0 + s dr|^2 = c + s (2 b + s a), never below 0 despite rounding
    d2 = s * a
    d2 += 2.0 * b
    d2 *= s
    d2 += c
    return np.maximum(d2, 0.0, out=d2), s


def _first_true(mask: np.ndarray) -> np.ndarray:
    """Index of the first True along axis 1, or the axis length when there is none."""
    return np.where(mask.any(axis=1), mask.argmax(axis=1), mask.shape[1])
