"""The encounter model: how the ownship flies one action, and whether that meets anything.

Every planner (and the kinematic episode runner) predicts with this one model, so a tree
search, its exhaustive reference and the campaign's "ground truth" agree on physics.

Ownship (vectorised over a batch of states): the action changes the bank *command* by one
``bank_step`` (clamped to the bank limit); the actual bank follows it at the autopilot's
roll-rate limit; the turn is coordinated, ``psi_dot = g tan(phi) / V``; the speed changes at
the commanded acceleration within the speed limits; the altitude moves towards the action's
height target (:meth:`PlannerConfig.height_target`: the goal's altitude for the paper's nine,
the ceiling or floor less a margin for the vertical set's climb and descend; what the JSBSim
autopilot is given) at the bounded climb rate, which the autopilot's speed priority cuts
at low speed (:func:`climb_rate`). Everything is in closed form over a grid of
sub-steps, so a segment costs a fixed number of numpy calls. The speed and heading are the
air's (airspeed, heading: what the aircraft's own instruments give); the steady wind the
planner knows (``PlannerConfig.wind_mps``) carries the air mass, and so every flown path, over
the ground, where the intruders' tracks and the goal are.

Intruders come as a :class:`Track`: their positions at the segment's sub-step instants,
predicted at constant velocity or, with their estimated turn rate, on a constant-rate turn
(:func:`uavxai.geometry.turn_positions`), and optionally a *margin* per intruder and instant
that the separation must clear on top of ``d_min``: ``uncertainty_k`` sigmas of the track's position
error, plus how far the intruder could stray from its prediction by banking anywhere within
its limit (:func:`manoeuvre_spread`, covered ``reach_horizon_s`` ahead), see
:func:`intruder_margin`. A line that enters that grown zone counts as a collision, and its
``min_sep`` is the distance left after the margin, so outcome and separation agree. Within
one sub-step both aircraft move on straight lines (the ownship on the exact chord of its
arc), so separation is known at *every* instant:

* collision (3-D separation below ``d_min`` anywhere, a pass-through between samples
  included) is always decided exactly: either the closest approach on every sub-step is
  solved in closed form, or the sampled distances prove there is none (no point of a chord is
  farther than half its length from an end);
* ``min_sep`` is solved exactly in the same cases (a sampled distance within half a relative
  sub-step of ``d_min``), or always with ``exact=True``; otherwise it is the minimum over the
  sub-step instants, which overstates the true minimum ``d`` by at most ``L^2 / (8 d)`` for a
  relative sub-step ``L``: under 2 m with the defaults (0.5 s sub-steps, 30 m/s, d > 65 m).

"Separation" is the 3-D distance, the conflict volume a sphere of ``d_min``, unless
``PlannerConfig.conflict_volume`` is "cylinder": then it is the cylinder's norm
``max(|r_xy|, aspect |r_h|)`` (``aspect`` = ``d_min`` / half-height), below ``d_min`` exactly
inside the cylinder, and everything above holds in that norm (its closest approach on a
chord: :func:`uavxai.geometry.cylinder_closest`; a chord is up to ``aspect`` times longer in
it, which the sampling's slack allows for; culling reaches the cylinder's corner).

Speed (a tree search calls this hundreds of times per decision): the ownship's motion
relative to its start, in its body frame, depends only on (speed, bank, bank command) and the
action, so :meth:`EncounterModel.expand` memoises it together with a circle bounding all the
set's paths; intruders (found through a grid, see :class:`Track`), goal and walls out of that
circle's reach are skipped, and the children's end states are only placed (:class:`Children`)
when the search goes on from one, or all at once when it is done (a search continues from
about one child in nine). Horizontal positions are complex numbers ``x + iy`` so that a
rotation is one multiplication.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from uavxai.avoidance.risk import RISK_SIGMAS
from uavxai.avoidance.types import Ownship, PlannerConfig
from uavxai.geometry import clip, cylinder_closest, turn_positions, turn_rate_of_bank
from uavxai.vocabulary import ACTIONS, Outcome

# Columns of a state row. VCMD: the vertical command of the vertical action set (+1 climb,
# 0 the leg's height, -1 descend), which persists like the bank command (0 with the paper's).
X, Y, H, V, PSI, PHI, PHI_CMD, VCMD = range(8)
STATE_DIM = 8

# The search's terminal codes: how a line of the tree ends, as the small integers its numpy
# arrays hold (SearchTree.terminal, Segment.event); no file holds them. Each is the Outcome at
# its index in TERMINALS, 0 an open line; OUTCOME_NAMES reads a code back as the Outcome value.
TERMINALS = (None, Outcome.GOAL, Outcome.COLLISION, Outcome.OUT_OF_BOUNDS, Outcome.TIMEOUT)
NONE, GOAL, COLLISION, OUT_OF_BOUNDS, TIMEOUT = range(len(TERMINALS))
OUTCOME_NAMES = tuple("" if o is None else o.value for o in TERMINALS)
# Paper eqs 13/14: goal 1, collision 0, time-out 0.1; leaving the map counts as a failure (0).
TERMINAL_VALUE = (math.nan, 1.0, 0.0, 0.0, 0.1)


def terminal_value(outcome: str) -> float:
    """The value of an episode's end by its name (``Outcome`` value): eq 14's."""
    return TERMINAL_VALUE[OUTCOME_NAMES.index(outcome)]


# By action index, over the whole table (the vertical set's climb and descend included).
_BANK_SIGN = np.array([a.bank for a in ACTIONS], dtype=float)
_ACCEL_SIGN = np.array([a.accel for a in ACTIONS], dtype=float)
_CLIMB_SIGN = np.array([a.climb for a in ACTIONS], dtype=int)
_EVENT_CODES = np.array([COLLISION, OUT_OF_BOUNDS, GOAL], dtype=np.int8)


def ownship_state(own: Ownship) -> np.ndarray:
    """One state row from the planner-API ownship."""
    phi = own.bank if own.phi is None else own.phi
    row = [own.x, own.y, own.h, own.speed, own.heading, phi, own.bank, own.vertical]
    return np.array(row, dtype=float)


# The resolution of the ownship's measured air motion (m/s): far below what a navigation
# system's velocity resolves or what moves the aircraft measurably over a search horizon, and
# coarse enough that in the kinematic world, whose ground velocity is exactly air velocity
# plus the steady wind, the gust comes out exactly zero.
GUST_RESOLUTION_MPS = 0.01


def ownship_air(own: Ownship, config: PlannerConfig) -> tuple[float, float]:
    """The motion (east, north) m/s of the air the ownship flies in, which carries its path
    over the ground: its measured ground velocity less its air velocity (``speed`` along
    ``heading``), i.e. the steady wind plus the gust of the moment. Gusts are correlated over
    many seconds at these speeds (moderate turbulence: about 0.9 after 1 s, 0.7 after 4 s),
    so the gust now carries the ownship over the search horizon as the wind does; without it
    the ownship is predicted from its air velocity and drifts off by the gust's 2-4 m/s, while
    the intruders, predicted from their ground tracks, carry theirs. The steady wind
    (``config.wind_mps``) when the air is steady (``config.gusts`` off), the ground velocity
    is not known, or it differs from it by less than :data:`GUST_RESOLUTION_MPS`."""
    wind = tuple(float(w) for w in config.wind_mps)
    if own.ground_velocity is None or not config.gusts:
        return wind
    air = (own.speed * math.sin(own.heading), own.speed * math.cos(own.heading))
    gust = [
        round((g - a - w) / GUST_RESOLUTION_MPS) * GUST_RESOLUTION_MPS
        for g, a, w in zip(own.ground_velocity, air, wind, strict=True)
    ]
    if not any(gust):
        return wind
    return (wind[0] + gust[0], wind[1] + gust[1])


def bank_command(current_cmd, action, cfg: PlannerConfig):
    """The bank command after ``action``: one step left/right of the current one, clamped."""
    lim = cfg.bank_limit_rad
    return clip(current_cmd + _BANK_SIGN[action] * cfg.bank_step_rad, -lim, lim)


def accel_command(action, cfg: PlannerConfig):
    return _ACCEL_SIGN[action] * cfg.accel_mps2


def climb_rate(speed, cfg: PlannerConfig):
    """The fastest the ownship climbs at airspeed ``speed`` (array or number): the climb-rate
    limit, cut by the autopilot's speed priority (``PlannerConfig.climb_speed_band_mps``)."""
    lo, hi = (cfg.speed_mps[0] + b for b in cfg.climb_speed_band_mps)
    return cfg.climb_rate_mps * clip((np.asarray(speed) - lo) / (hi - lo), 0.0, 1.0)


def vertical_command(current, action):
    """The vertical command after ``action``: climb and descend step it one place along
    (descend, the leg's height, climb), the paper's nine keep it, as bank actions step the
    bank command and hold keeps it."""
    return clip(current + _CLIMB_SIGN[action], -1, 1)


# ---------------------------------------------------------------------------------- intruders
@dataclass(frozen=True)
class Track:
    """Intruder positions at a segment's sub-step instants, and a ball bounding each path.

    Between two instants an intruder moves in a straight line, so the ball around its samples
    holds its whole path. ``Track.of(pos, index_distance=d)`` also files every intruder in a
    grid of the horizontal plane (when :meth:`near` is first asked), so that queries up to
    ``d`` cost a dictionary look-up when nothing is near (the usual case in a tree search).
    """

    pos: np.ndarray  # (n+1, N, 3)
    xy: np.ndarray = field(repr=False)  # (n+1, N) complex x + iy
    h: np.ndarray = field(repr=False)  # (n+1, N)
    centre: np.ndarray = field(repr=False)  # (N, 3)
    radius: np.ndarray = field(repr=False)  # (N,)
    step_max: float = 0.0  # longest straight piece of any path (one sub-step), m
    index_distance: float = 0.0  # queries up to this distance use the grid
    cells: dict[tuple[int, int], list] = field(default_factory=dict, repr=False)
    # (n+1, N) separation needed beyond d_min at each instant (what the intruder might do,
    # how uncertain its track is), non-decreasing in time; None: none. The ball above
    # includes it, so that culling by ``near`` stays exact.
    margin: np.ndarray | None = field(default=None, repr=False)
    # (n+1, N) the track's 1-sigma position error at each instant when the search weighs it
    # as a probability (PlannerConfig.risk "probability", uavxai.avoidance.risk); None: not.
    # The ball reaches RISK_SIGMAS of it beyond the margin, where the chance is counted.
    sigma: np.ndarray | None = field(default=None, repr=False)
    # (n+1, N) with a vertical margin of its own (PlannerConfig.vertical_reach_mps): how much
    # the compiled search stretches the height difference to a track, (d_min + margin) /
    # (d_min + vertical margin) >= 1, so that the sphere of d_min + margin in that norm is a
    # spheroid as tall as d_min + the vertical margin (kernel._hits); None: the sphere.
    vscale: np.ndarray | None = field(default=None, repr=False)

    @classmethod
    def of(
        cls,
        pos: np.ndarray,
        index_distance: float = 0.0,
        margin: np.ndarray | None = None,
        grow: float = 1.0,
        sigma: np.ndarray | None = None,
    ) -> Track:
        """``grow``: the ball holds the margin times this (the conflict cylinder's corner
        reaches ``PlannerConfig.cull_factor`` times its radius, margin included);
        ``sigma``: see the field. Several tree levels at once: :meth:`levels`."""
        pos = np.asarray(pos, dtype=float)
        if pos.ndim != 3 or pos.shape[2] != 3 or pos.shape[0] < 2:
            raise ValueError(f"intruder positions must be (n+1, N, 3) with n >= 1, got {pos.shape}")
        for name, extra in (("margin", margin), ("sigma", sigma)):
            if extra is not None and np.shape(extra) != pos.shape[:2]:
                raise ValueError(f"{name} must be {pos.shape[:2]}, got {np.shape(extra)}")
        margins = None if margin is None else [margin]
        sigmas = None if sigma is None else [sigma]
        return cls.levels(pos[None], index_distance, margins, grow, sigmas)[0]

    @classmethod
    def levels(
        cls,
        pos: np.ndarray,
        index_distance: float = 0.0,
        margins: Sequence[np.ndarray] | np.ndarray | None = None,
        grow: float = 1.0,
        sigmas: Sequence[np.ndarray] | np.ndarray | None = None,
    ) -> list[Track]:
        """:meth:`of` for L tree levels at once: ``pos`` (L, n+1, N, 3), ``margins[l]`` and
        ``sigmas[l]`` (n+1, N) level ``l``'s (None: none at any level). Every number is
        computed per level as :meth:`of` says (a level's track is the same in a batch or
        alone); one pass over the levels costs less than a pass each."""
        pos = np.asarray(pos, dtype=float)
        centre = 0.5 * (pos.min(axis=1) + pos.max(axis=1))  # (L, N, 3)
        radius = np.sqrt(np.max(np.sum((pos - centre[:, None]) ** 2, axis=3), axis=1))
        steps = np.sqrt(np.sum(np.diff(pos, axis=1) ** 2, axis=3))  # (L, n, N)
        step_max = steps.max(axis=(1, 2)).tolist() if steps.size else [0.0] * len(pos)
        xy = pos[..., 0] + 1j * pos[..., 1]
        h = np.ascontiguousarray(pos[..., 2])
        index_distance = index_distance if pos.shape[2] >= _INDEX_MIN else 0.0
        out = []
        for lv in range(len(pos)):
            r = radius[lv]
            margin = None if margins is None else np.asarray(margins[lv], dtype=float)
            if margin is not None:
                if not np.any(margin):
                    margin = None
                else:
                    r = r + grow * margin.max(axis=0, initial=0.0)
            sigma = None if sigmas is None else np.asarray(sigmas[lv], dtype=float)
            if sigma is not None:
                r = r + RISK_SIGMAS * sigma.max(axis=0, initial=0.0)
            out.append(cls(pos=pos[lv], xy=xy[lv], h=h[lv], centre=centre[lv], radius=r,
                           step_max=step_max[lv], index_distance=index_distance, margin=margin,
                           sigma=sigma))  # fmt: skip
        return out  # filed in its grid when first asked (the compiled search never asks)

    def _file(self, distance: float) -> None:
        """Each intruder goes into every cell that its ball grown by ``distance`` touches, so
        a query point's cell lists every intruder it may be near. Cells hold (index, x, y, h,
        radius) tuples: the few candidates are tested in Python."""
        cell = self.cell_m
        for j, ((x, y, h), r) in enumerate(
            zip(self.centre.tolist(), self.radius.tolist(), strict=True)
        ):
            grown = r + distance
            entry = (j, x, y, h, r)
            for i in range(math.floor((x - grown) / cell), math.floor((x + grown) / cell) + 1):
                for k in range(math.floor((y - grown) / cell), math.floor((y + grown) / cell) + 1):
                    self.cells.setdefault((i, k), []).append(entry)

    @property
    def cell_m(self) -> float:
        """Side of the grid's cells: large, so that an intruder sits in few of them."""
        return 2.0 * self.index_distance

    @property
    def n(self) -> int:
        """Number of sub-steps."""
        return self.pos.shape[0] - 1

    @property
    def count(self) -> int:
        return self.pos.shape[1]

    def near(self, centre: Sequence[float], distance: float) -> np.ndarray:
        """Indices of intruders whose path may come within ``distance`` of ``centre``."""
        if distance <= self.index_distance:
            if not self.cells:
                self._file(self.index_distance)
            x, y, h = centre
            size = self.cell_m
            found = [
                j
                for j, cx, cy, ch, r in self.cells.get(
                    (math.floor(x / size), math.floor(y / size)), ()
                )
                if (cx - x) ** 2 + (cy - y) ** 2 + (ch - h) ** 2 <= (distance + r) ** 2
            ]
            return np.array(found, dtype=int) if found else _NO_INTRUDERS
        d = self.centre - np.asarray(centre, dtype=float)
        return np.flatnonzero(np.einsum("ij,ij->i", d, d) <= (distance + self.radius) ** 2)


MEMO_LIMIT = 50_000  # body motions kept from one search to the next (memory)
_BATCH_MEMO = 4096  # EncounterModel._body's entries before it starts afresh ...
_BATCH_CELLS = 256  # ... each of at most this many rows x sample instants: at most ~25 MB
_INDEX_MIN = 6  # below this many intruders a plain distance test is as fast as the grid
_NO_INTRUDERS = np.zeros(0, dtype=int)
_NO_INTRUDERS.flags.writeable = False


def manoeuvre_spread(
    vel: np.ndarray, turn_rate: np.ndarray, t: np.ndarray, bank_limit_rad: float | np.ndarray
) -> np.ndarray:
    """(T, N) how far from its constant-turn prediction an aircraft can be at times ``t``
    if it changes its bank now to anything within ``bank_limit_rad`` (one for all, or (N,)
    each its own: a coordinated turn at its speed, turn rates within +-g tan(limit) / V): the
    larger of the two extreme turns' distances from the nominal one, kept non-decreasing in
    time. The set of positions reachable by then lies within this distance of the nominal
    position. ``t`` (..., T): several runs of times at once, (..., T, N), each kept
    non-decreasing on its own."""
    speed = np.maximum(np.hypot(vel[:, 0], vel[:, 1]), 1.0)
    w_max = turn_rate_of_bank(bank_limit_rad, speed)
    w = clip(np.asarray(turn_rate, dtype=float), -w_max, w_max)
    flat = np.ravel(t)
    nominal = turn_positions(np.zeros_like(vel), vel, flat, w)
    spread = np.zeros((flat.size, vel.shape[0]))
    for extreme in (w_max, -w_max):
        d = turn_positions(np.zeros_like(vel), vel, flat, extreme) - nominal
        spread = np.maximum(spread, np.hypot(d[..., 0], d[..., 1]))
    return np.maximum.accumulate(spread.reshape(*np.shape(t), -1), axis=-2)


def intruder_margin(
    config: PlannerConfig,
    vel: np.ndarray,
    turn_rate: np.ndarray,
    sigma_m: np.ndarray | None = None,
    sigma_v: np.ndarray | None = None,
    bank_limit_rad: np.ndarray | None = None,
) -> Callable[[np.ndarray], np.ndarray] | None:
    """The separation needed beyond ``d_min`` from each intruder, as a function of the time
    ``t`` (T,) from now, (T, N); None when there is none. ``bank_limit_rad`` (N,): each
    intruder's own bank limit (issue 31); None: ``intruder_bank_limit_deg`` for every one.

    Two parts add up: the uncertainty (with ``risk="probability"`` only over the first
    ``risk_wall_s`` seconds, none beyond them nor when that is None), ``uncertainty_k`` sigmas of
    ``sqrt(sigma_m^2 + (sigma_v t_v)^2 + own(t)^2)``, the track's and the ownship model's own
    (``own_error_10s_m`` at 10 s, as ``t^1.5``), with ``t_v = min(t,
    uncertainty_horizon_s)`` (``t`` when None); and with ``intruder_model="reachable"`` what the
    intruder could do next, :func:`manoeuvre_spread` at ``min(t, reach_horizon_s)``. The
    reachable set is covered only that far ahead because re-planning every decision period
    answers what comes later; beyond it the whole set would cover most of a crowded sky (a
    15 m/s intruder can be anywhere within 240 m of its prediction after 16 s).
    """
    n = vel.shape[0]
    # With risk as a probability the track error is no wall (track_sigma gives it to the
    # search as a chance), except over a line's first risk_wall_s seconds when set: what the
    # track may do before the ownship can answer it is fenced off, the rest weighed.
    wall_s = config.risk_wall_s if config.risk == "probability" else None
    k = 0.0 if config.risk == "probability" and wall_s is None else config.uncertainty_k
    sigma = track_sigma(config, n, sigma_m, sigma_v)
    reach = config.intruder_model == "reachable" and config.reach_horizon_s > 0
    uncertain = k > 0 and sigma is not None
    if not n or not (reach or uncertain):
        return None
    limit: float | np.ndarray = math.radians(config.intruder_bank_limit_deg)
    if bank_limit_rad is not None:
        limit = bank_limit_rad
    horizon = config.reach_horizon_s
    air = np.asarray(vel, dtype=float) - np.array([*config.wind_mps, 0.0])

    def margin(t: np.ndarray) -> np.ndarray:  # t (..., T): (..., T, N)
        out = np.zeros((*t.shape, n))
        if uncertain:  # with risk_wall_s none beyond it: the chance counts the error there
            wall = k * sigma(t)
            out += wall if wall_s is None else np.where((t <= wall_s)[..., None], wall, 0.0)
        if reach:  # turns differ through the air: the wind carries all of them alike
            out += manoeuvre_spread(air, turn_rate, np.minimum(t, horizon), limit)
        return out

    return margin


def vertical_margin(
    config: PlannerConfig, sigma_h: np.ndarray, sigma_vh: np.ndarray
) -> Callable[[np.ndarray], np.ndarray] | None:
    """The vertical separation needed beyond ``d_min`` from each of N intruders at times ``t``
    (..., T), (..., T, N), when the margin has a vertical part of its own
    (``vertical_reach_mps``; None when not): what it could climb or descend,
    ``vertical_reach_mps`` over ``min(t, reach_horizon_s)`` (the turn cover's horizon, with
    ``intruder_model="reachable"``), plus ``uncertainty_k`` sigmas of its vertical track error
    (:func:`track_sigma` of the vertical position and velocity sigmas ``sigma_h``,
    ``sigma_vh`` (N,)). Why: the horizontal margin (turns, horizontal velocity error) stood as
    tall as it is wide and fenced off a thin traffic layer as a slab (issue 31, sep32)."""
    reach_mps = config.vertical_reach_mps
    if reach_mps is None:
        return None
    n = np.size(sigma_h)
    sigma = track_sigma(config, n, sigma_h, sigma_vh) if config.uncertainty_k > 0 else None
    reach = config.intruder_model == "reachable" and config.reach_horizon_s > 0
    horizon = config.reach_horizon_s

    def margin(t: np.ndarray) -> np.ndarray:
        tt = np.asarray(t, dtype=float)
        out = np.zeros((*tt.shape, n))
        if sigma is not None:
            out += config.uncertainty_k * sigma(tt)
        if reach:
            out += (reach_mps * np.minimum(tt, horizon))[..., None]
        return out

    return margin


def track_sigma(
    config: PlannerConfig,
    n: int,
    sigma_m: np.ndarray | None = None,
    sigma_v: np.ndarray | None = None,
) -> Callable[[np.ndarray], np.ndarray] | None:
    """The 1-sigma position error (per axis) of ``n`` tracks predicted ``t`` (..., T)
    seconds ahead, (..., T, N): ``sqrt(sigma_m^2 + (sigma_v t_v)^2 + own(t)^2)``, the track's
    and the ownship model's own (``own_error_10s_m`` at 10 s, as ``t^1.5``), with ``t_v =
    min(t, uncertainty_horizon_s)`` (``t`` when None). None when there is none."""
    sm = np.zeros(n) if sigma_m is None else np.asarray(sigma_m, dtype=float)
    sv = np.zeros(n) if sigma_v is None else np.asarray(sigma_v, dtype=float)
    own = config.own_error_10s_m / 10.0**1.5
    if not n or not (np.any(sm) or np.any(sv) or own > 0):
        return None
    vel_horizon = config.uncertainty_horizon_s

    def sigma(t: np.ndarray) -> np.ndarray:
        tt = np.asarray(t, dtype=float)[..., None]
        tv = tt if vel_horizon is None else np.minimum(tt, vel_horizon)
        return np.sqrt(sm ** 2 + (sv * tv) ** 2 + own**2 * tt**3)

    return sigma


# ----------------------------------------------------------------------------------- segments
@dataclass(slots=True)  # not frozen: built hundreds of times per decision
class Segment:
    """A batch of ownship states, each flying one action for the same duration.

    ``min_sep``, ``closest`` and ``t_closest`` count the segment only up to its event: after
    reaching the goal (or colliding) nothing more is flown. Intruders that cannot come within
    ``d_min`` are skipped unless flown with ``cull=False``; a segment with none in reach
    reports ``min_sep`` inf and ``closest`` -1.
    """

    end: np.ndarray | None  # (B, 7) states at the end (None from EncounterModel.expand)
    min_sep: np.ndarray  # (B,) smallest 3-D distance to an intruder, m (see module docstring)
    closest: np.ndarray  # (B,) index of that intruder
    t_closest: np.ndarray  # (B,) seconds from the segment's start to that closest approach
    event: np.ndarray  # (B,) int8 terminal code, NONE when nothing happened
    t_event: np.ndarray  # (B,) seconds from the start to the start of the event's sub-step
    xy: np.ndarray | None = field(repr=False)  # (B, n+1) complex positions at the sub-steps
    hs: np.ndarray | None = field(repr=False)  # (B or 1, n+1) altitudes at the sub-steps

    @property
    def samples(self) -> np.ndarray | None:
        """(B, n+1, 3) positions at the sub-step instants (None: not computed)."""
        if self.xy is None or self.hs is None:
            return None
        h = np.broadcast_to(self.hs, self.xy.shape)
        return np.stack([self.xy.real, self.xy.imag, h], axis=-1)


@dataclass(frozen=True)
class _BodyMotion:
    """Motion relative to the start, in the start's body frame: ``right + i forward``."""

    z: np.ndarray  # (B, n+1) complex
    dpsi: np.ndarray  # (B,) heading change, rad
    v_end: np.ndarray  # (B,)
    phi_end: np.ndarray  # (B,)
    phi_cmd: np.ndarray  # (B,)
    ball: complex = 0j  # centre of a circle holding every row's path (body frame) ...
    ball_r: float = 0.0  # ... and its radius
    step_max: float = 0.0  # longest horizontal sub-step chord of any row
    template: np.ndarray | None = None  # (B, 7) end states with V, PHI, PHI_CMD filled in
    z_end: np.ndarray | None = None  # (B,) the last column of z
    rows: tuple = ()  # per row (z_end, dpsi, v_end, phi_end, phi_cmd) as Python numbers
    rise: np.ndarray | None = None  # (B, n+1) the most it can have climbed by each instant
    rise_end: tuple[float, ...] = ()  # per row, the last column of rise
    # per row (z_end.real, z_end.imag, dpsi, v_end, phi_end, phi_cmd, rise_end): the compiled
    # search's table (uavxai.avoidance.kernel)
    table: np.ndarray | None = None
    children: tuple = ()  # per row, the memo key of the child's motion (see motion_key)


@dataclass(slots=True)
class Children:
    """Where the children of one state (one per action of the set) end, kept as the parent's
    placement of the memoised body motion; :meth:`state` places one child in plain Python and
    :func:`place_children` places many at once."""

    origin: complex  # where the air mass carries the parent's x + iy by the segment's end
    rot: complex  # e^{-i psi}: body frame to world
    h_end: tuple[float, ...]  # per action (with the vertical set, per vertical command)
    psi: float
    body: _BodyMotion
    vcmd: tuple[int, ...]  # per action: the vertical command it leaves

    def state(self, action: int) -> list[float]:
        """The child's state row (as a list)."""
        z_end, dpsi, v_end, phi_end, phi_cmd = self.body.rows[action]
        p = self.origin + z_end * self.rot
        psi = (self.psi + dpsi) % _TAU
        return [p.real, p.imag, self.h_end[action], v_end, psi, phi_end, phi_cmd, self.vcmd[action]]

    def position(self, action: int) -> tuple[float, float, float]:
        p = self.origin + self.body.rows[action][0] * self.rot
        return p.real, p.imag, self.h_end[action]


_TAU = 2.0 * math.pi


def place_children(blocks: Sequence[Children]) -> np.ndarray:
    """(K * len(blocks), 7) end states of every child of ``blocks`` (K per block), in order,
    vectorised."""
    if not blocks:
        return np.zeros((0, STATE_DIM))
    origin = np.array([b.origin for b in blocks])
    rot = np.array([b.rot for b in blocks])
    h_end = np.array([b.h_end for b in blocks])
    psi = np.array([b.psi for b in blocks])
    body = [b.body for b in blocks]
    xy = origin[:, None] + np.stack([b.z_end for b in body]) * rot[:, None]
    end = np.stack([b.template for b in body])
    end[:, :, X] = xy.real
    end[:, :, Y] = xy.imag
    end[:, :, H] = h_end
    end[:, :, VCMD] = np.array([b.vcmd for b in blocks])
    end[:, :, PSI] = np.mod(psi[:, None] + np.stack([b.dpsi for b in body]), _TAU)
    return end.reshape(-1, STATE_DIM)


@dataclass(slots=True)
class _Intruders:
    """The intruders a batch is checked against, laid out to broadcast against its rows."""

    xy: np.ndarray  # (1 or B, n+1, k) complex
    h: np.ndarray  # (1 or B, n+1, k)
    ids: np.ndarray  # (k,) their indices in the track(s)
    step_max: float  # longest straight piece of any of their paths
    margin: np.ndarray | None = None  # (1 or B, n+1, k) separation needed beyond d_min

    @classmethod
    def of(cls, track: Track, near: np.ndarray) -> _Intruders:
        margin = None if track.margin is None else track.margin[:, near][None]
        return cls(track.xy[:, near][None], track.h[:, near][None], near, track.step_max, margin)


# Where a batch of paths stays: a vertical cylinder.
_Cylinder = tuple[float, float, float, float, float]  # x, y, h, horizontal radius, half-height


def _frozen(a: np.ndarray) -> np.ndarray:
    a.flags.writeable = False
    return a


# A body motion's memo key: speed, bank, bank command (rounded) and the segment's duration.
_MotionKey = tuple[float, float, float, float]


def motion_keys(v, phi, cmd, duration: float) -> list[_MotionKey]:
    """The memo keys of rows with speeds ``v``, banks ``phi`` and bank commands ``cmd``
    (arrays). Keys are rounded far below any physical effect so that states reached along
    different float paths (20 + 4 - 4) share an entry; the motion is computed from the key
    itself, so the answer never depends on what the memo already holds. (numpy's rounding,
    for whole batches at once.)"""
    d = float(duration)
    rounded = zip(np.round(v, 6).tolist(), np.round(phi, 9).tolist(), np.round(cmd, 9).tolist(),
                  strict=True)  # fmt: skip
    return [(a, b, c, d) for a, b, c in rounded]


def motion_key(v: float, phi: float, cmd: float, duration: float) -> _MotionKey:
    """:func:`motion_keys` of one row."""
    return motion_keys(np.array([v], dtype=float), np.array([phi], dtype=float),
                       np.array([cmd], dtype=float), duration)[0]  # fmt: skip


class EncounterModel:
    """Closed-loop ownship kinematics and intruder tracks (see the module docstring)."""

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config
        self._roll = math.radians(config.roll_rate_limit_deg_s)
        self._memo: dict[tuple[float, float, float, float], _BodyMotion] = {}
        self._batches: dict[tuple, _BodyMotion] = {}  # _body's memo, by its inputs' bits
        self._band: tuple[float, float] | None = None  # hold_speed_band
        self._substeps: dict[float, int] = {}
        # ground drift of the air the ownship flies in, x + iy m/s (see carry_ownship); the
        # intruders' tracks are in the steady wind, config.wind_mps
        self._wind = complex(*config.wind_mps)
        self._drifts: dict[tuple[float, int], np.ndarray] = {}
        k = config.n_actions
        self.actions = np.arange(k)  # the action set: the first k of the table
        self._climbs = _CLIMB_SIGN[:k].tolist()
        self.climbs = _frozen(_CLIMB_SIGN[:k].astype(np.int64))  # per action: +1 climb, -1 descend
        self.vertical = any(self._climbs)
        self._level = (0,) * k  # the vertical commands of the paper's children
        # What a segment with nothing in reach reports, shared and read-only.
        self._quiet = (
            _frozen(np.full(k, np.inf)),
            _frozen(np.full(k, -1)),
            _frozen(np.zeros(k)),
            _frozen(np.zeros(k, dtype=np.int8)),
            _frozen(np.full(k, np.nan)),
        )

    # ------------------------------------------------------------------------------- helpers
    def hold_speed_band(self, band: tuple[float, float] | None) -> None:
        """From now on the ownship flies airspeeds within ``band`` (None: the config's
        ``speed_mps``): an operator's speed (``Ownship.speed_band``). A planner sets it once
        per decision, with :meth:`carry_ownship`."""
        band = None if band is None else (float(band[0]), float(band[1]))
        if band != self._band:
            self._band = band
            self._memo.clear()
            self._batches.clear()

    def carry_ownship(self, air: tuple[float, float]) -> None:
        """From now on the ownship's paths drift with ``air`` (east, north) m/s, the motion
        of the air it flies in (:func:`ownship_air`), instead of the steady wind; the
        intruders' tracks keep the steady wind. A planner sets it once per decision, before
        it predicts and searches."""
        wind = complex(*air)
        if wind != self._wind:
            self._wind = wind
            self._drifts.clear()

    def substeps(self, duration: float) -> int:
        """Sub-steps of a segment: the fewest of at most ``substep_s`` each."""
        n = self._substeps.get(duration)
        if n is None:
            n = self._substeps[duration] = max(
                1, math.ceil(duration / self.config.substep_s - 1e-9)
            )
        return n

    def predict(
        self,
        pos: np.ndarray,
        vel: np.ndarray,
        duration: float,
        t0: float = 0.0,
        *,
        index: bool = True,
        turn_rate: np.ndarray | None = None,
        margin: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> Track:
        """Track over [t0, t0 + duration] of intruders now at ``pos`` with velocity ``vel``:
        constant velocity, or with ``turn_rate`` (N,) rad/s (+ clockwise, a right turn) a
        constant-rate turn at constant speed; ``index``: filed for quick :meth:`Track.near`
        queries within an ownship's reach. ``margin(t)`` gives the (T, N) separation needed
        beyond ``d_min`` at times ``t`` (T,) from now (see :func:`intruder_margin`)."""
        return self.predict_levels(
            pos, vel, duration, [t0], index=index, turn_rate=turn_rate, margin=margin
        )[0]

    def predict_levels(
        self,
        pos: np.ndarray,
        vel: np.ndarray,
        duration: float,
        starts: Sequence[float],
        *,
        index: bool = True,
        turn_rate: np.ndarray | None = None,
        margin: Callable[[np.ndarray], np.ndarray] | None = None,
        sigma: Callable[[np.ndarray], np.ndarray] | None = None,
    ) -> list[Track]:
        """:meth:`predict` over ``[t0, t0 + duration]`` for every ``t0`` of ``starts`` (a
        tree's levels), computed in one batch; ``margin(t)`` is given ``t`` (n+1,) for one
        level, as :meth:`predict` says, and (levels, n+1) for several; ``sigma(t)`` alike
        (:func:`track_sigma`: the tracks' errors, when risk is a probability)."""
        n = self.substeps(duration)
        t = np.array(starts, dtype=float)[:, None] + (duration / n) * np.arange(n + 1)
        distance = self.reach(0.0, duration) + self.config.cull_m if index else 0.0
        extra = None
        if margin is not None:
            extra = margin(t[0])[None] if len(starts) == 1 else margin(t)
        wind = self.config.wind_mps
        pos = turn_positions(pos, vel, t.ravel(), turn_rate, wind).reshape(*t.shape, -1, 3)
        errors = None if sigma is None else sigma(t)
        return Track.levels(pos, distance, extra, self.config.cull_factor, errors)

    def reach(self, speed: float, duration: float) -> float:
        """The farthest (3-D) an ownship at ``speed`` can get from its start in ``duration``."""
        v_top = max(self.config.speed_mps[1], speed) + abs(self._wind)
        return math.hypot(v_top, self.config.climb_rate_mps) * duration

    def drift(self, duration: float, n: int) -> np.ndarray:
        """(n+1,) complex: how far the wind carries an aircraft by each sub-step instant."""
        key = (float(duration), n)
        d = self._drifts.get(key)
        if d is None:
            d = self._drifts[key] = _frozen(self._wind * (duration / n) * np.arange(n + 1))
        return d

    def leaf_value(self, positions: np.ndarray, goal: np.ndarray) -> np.ndarray:
        """Paper eq 13 for non-terminal states: 1 - d(o, g) / d_max."""
        d = np.sqrt(
            np.einsum("...i,...i->...", positions[..., :3] - goal, positions[..., :3] - goal)
        )
        return 1.0 - d / self.config.d_max

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
        exact: bool = False,
    ) -> Segment:
        """Fly ``actions`` (B,) from ``states`` (B, 7) for ``duration`` seconds.

        ``track`` holds the intruders at this segment's sub-step instants (``predict`` makes
        it). ``cull=False`` measures every intruder, in reach or not; ``exact=True`` solves
        the closest approach on every sub-step even when nothing comes near.
        """
        n = self._check(duration, track)
        body, xy, hs, end, box = self._place(states, actions, goal, duration, n)
        reach = math.hypot(box[3], box[4]) + self.config.cull_m
        near = track.near(box[:3], reach) if cull else np.arange(track.count)
        seen = _Intruders.of(track, near)
        own_step = self._own_step(body, duration / n)
        return self._events(end, xy, hs, goal, seen, box, duration / n, own_step, exact)

    def fly_levels(
        self,
        states: np.ndarray,
        actions: np.ndarray,
        levels: np.ndarray,
        goal: np.ndarray,
        duration: float,
        tracks: Sequence[Track],
    ) -> Segment:
        """As ``fly(..., cull=False, exact=True)``, but row ``b`` meets the intruders of
        ``tracks[levels[b]]``: the edges of several tree levels in one batch."""
        n = max(self._check(duration, t) for t in tracks)
        body, xy, hs, end, box = self._place(states, actions, goal, duration, n)
        margin = None
        if any(t.margin is not None for t in tracks):
            margin = np.stack([np.zeros(t.h.shape) if t.margin is None else t.margin
                               for t in tracks])[levels]  # fmt: skip
        seen = _Intruders(
            xy=np.stack([t.xy for t in tracks])[levels],
            h=np.stack([t.h for t in tracks])[levels],
            ids=np.arange(tracks[0].count),
            step_max=max(t.step_max for t in tracks),
            margin=margin,
        )
        own_step = self._own_step(body, duration / n)
        return self._events(end, xy, hs, goal, seen, box, duration / n, own_step, True)

    def fly_all_actions(
        self, state: np.ndarray, goal: Sequence[float], duration: float, track: Track
    ) -> Segment:
        """The children of one state, one per action of the set, in action order: ``fly``
        with every action, memoised.

        When nothing (intruder, goal, wall) is within reach, the sub-step positions are not
        computed: ``xy``, ``hs`` and ``samples`` are then None.
        """
        placed, seg = self.expand(state.tolist(), goal, duration, track)
        seg.end = place_children([placed])
        return seg

    def expand(
        self, state: Sequence[float], goal: Sequence[float], duration: float, track: Track
    ) -> tuple[Children, Segment]:
        """:meth:`fly_all_actions` as a tree search needs it, the hot path: the children's end
        states come as a :class:`Children` placement (``Segment.end`` is None), because a
        search goes on from few of the children it scores."""
        cfg = self.config
        n = self._check(duration, track)
        x, y, h, v, psi, phi, cmd = state[:7]
        key = motion_key(v, phi, cmd, duration)
        body = self._memo.get(key) or self._remember([key], n)[0]
        origin = complex(x, y)
        rot = complex(math.cos(psi), -math.sin(psi))
        sink = cfg.climb_rate_mps * duration
        vcmd = self._level
        if self.vertical:  # each vertical command has its height target
            vc = int(state[VCMD]) if len(state) > VCMD else 0
            vcmd = tuple(min(max(vc + c, -1), 1) for c in self._climbs)
            target = {m: cfg.height_target(m, goal[2]) for m in set(vcmd)}
            heights = [target[m] for m in vcmd]
        else:
            heights = [goal[2]] * self.actions.size
        h_ends = tuple(
            h + min(max(t - h, -sink), rise) for t, rise in zip(heights, body.rise_end, strict=True)
        )
        drift = self.drift(duration, n)
        placed = Children(origin + drift[-1], rot, h_ends, psi, body, vcmd)

        half = 0.5 * drift[-1]  # the paths' circle, carried by the wind: centre + half, r + |half|
        c = origin + body.ball * rot + half
        h_lo, h_hi = min(h, *h_ends), max(h, *h_ends)
        box = (c.real, c.imag, 0.5 * (h_lo + h_hi), body.ball_r + abs(half), 0.5 * (h_hi - h_lo))
        near = track.near(box[:3], math.hypot(box[3], box[4]) + cfg.cull_m)
        if not near.size and not self._near_goal(box, goal) and not self._near_wall(box):
            return placed, Segment(None, *self._quiet, xy=None, hs=None)  # no sample needed
        xy = origin + body.z * rot + drift
        if h_lo == h_hi:
            hs = np.full((1, n + 1), h)
        else:
            hs = h + clip(np.array(heights)[:, None] - h, self._sink(duration, n), body.rise)
        own_step = self._own_step(body, duration / n)
        seen = _Intruders.of(track, near)
        return placed, self._events(None, xy, hs, goal, seen, box, duration / n, own_step, False)

    def _remember(self, keys: Sequence[_MotionKey], n: int) -> list[_BodyMotion]:
        """Compute and memoise the body motions of ``keys`` (not yet memoised), one batch."""
        k = self.actions.size
        v_, phi_, cmd_ = (np.repeat(np.array([key[i] for key in keys]), k) for i in range(3))
        actions = np.tile(self.actions, len(keys))
        bodies = self._bodies(v_, phi_, cmd_, actions, keys[0][3], n, len(keys))
        self._memo.update(zip(keys, bodies, strict=True))
        return bodies

    def motions(
        self, state: Sequence[float], duration: float, levels: int
    ) -> tuple[list[_MotionKey], np.ndarray]:
        """Every body-motion key a tree search from ``state`` can expand within ``levels``
        tree levels (the root's first), memoised level by level in one batch each, and the
        (M, K) table of the keys' indices that each key's children have (-1 on the last
        level, whose children are never expanded). A search needs a few dozen; one at a time
        they cost more than the rest of the search."""
        if len(self._memo) > MEMO_LIMIT:
            # Bounded between searches, never within one: a search holds the keys it was given
            # (a clear in mid-search lost them: a KeyError some hundred JSBSim encounters into
            # a campaign, when the memo first passed its bound).
            self._memo.clear()
        n = self.substeps(duration)
        keys = [motion_key(state[V], state[PHI], state[PHI_CMD], duration)]
        index = {keys[0]: 0}
        child = np.full((1, self.actions.size), -1, dtype=np.int64)
        frontier = keys[:]
        for level in range(levels):
            missing = [key for key in frontier if key not in self._memo]
            if missing:
                self._remember(missing, n)
            if level == levels - 1:
                break
            nxt = []
            for key in frontier:
                row = child[index[key]]
                for a, kid in enumerate(self._memo[key].children):
                    if kid not in index:
                        index[kid] = len(keys)
                        keys.append(kid)
                        nxt.append(kid)
                    row[a] = index[kid]
            child = np.concatenate([child, np.full((len(nxt), child.shape[1]), -1)])
            frontier = nxt
        return keys, child

    def motion(self, key: _MotionKey) -> _BodyMotion:
        """The memoised body motion of ``key`` (see :meth:`motions`)."""
        return self._memo[key]

    def fly_commanded(
        self, states: np.ndarray, bank_cmd: np.ndarray, duration: float, *, samples: bool = True
    ) -> tuple[np.ndarray | None, np.ndarray]:
        """Fly ``states`` (B, 7) for ``duration`` with the bank commanded straight to
        ``bank_cmd`` (B,) (clamped to the limit), speed and altitude held, in the wind: how
        the other aircraft fly. Returns the (n+1, B, 3) positions at the sub-step instants
        (a Track's layout; None with ``samples=False``, for a caller that only moves the
        aircraft on) and the (B, 7) end states. No event checks."""
        n = self.substeps(duration)
        hold = np.full(len(states), 4)  # hold bank, hold speed: the command is bank_cmd itself
        body = self._body(states[:, V], states[:, PHI], bank_cmd, hold, duration, n)
        xy = (
            (states[:, X, None] + 1j * states[:, Y, None])
            + body.z * np.exp(-1j * states[:, PSI, None])
            + self.drift(duration, n)
        )
        end = self._end(xy[:, -1], states[:, H], states[:, PSI], body)
        if not samples:
            return None, end
        pos = np.stack([xy.real.T, xy.imag.T, np.broadcast_to(states[:, H], xy.T.shape)], axis=-1)
        return pos, end

    def fly_end(
        self, states: np.ndarray, actions: np.ndarray, goal: np.ndarray, duration: float
    ) -> np.ndarray:
        """The (B, 8) end states of ``fly(states, actions, goal, duration, ...)``, the same to
        the bit, without the sub-step samples' events: how the kinematic world moves the
        ownship, which needs nothing else of the segment."""
        return self._sampled(states, actions, goal, duration, self.substeps(duration))[3]

    def _place(self, states, actions, goal, duration: float, n: int):
        """Body motion, sub-step positions, end states and a bounding cylinder of a batch."""
        body, xy, hs, end = self._sampled(states, actions, goal, duration, n)
        # The cylinder: centred on the samples' box, radius to the farthest, half-height.
        lo = np.array([xy.real.min(), xy.imag.min(), hs.min()])
        hi = np.array([xy.real.max(), xy.imag.max(), hs.max()])
        cx, cy, ch = (0.5 * (lo + hi)).tolist()
        r_xy = float(np.abs(xy - complex(cx, cy)).max())
        box: _Cylinder = (cx, cy, ch, r_xy, 0.5 * float(hi[2] - lo[2]))
        return body, xy, hs, end, box

    def _sampled(self, states, actions, goal, duration: float, n: int):
        """Body motion, sub-step positions and end states of a batch."""
        states = np.asarray(states, dtype=float)
        body = self._body(states[:, V], states[:, PHI], states[:, PHI_CMD], actions, duration, n)
        p = states[:, X, None] + 1j * states[:, Y, None]
        xy = p + body.z * np.exp(-1j * states[:, PSI, None]) + self.drift(duration, n)
        h0 = states[:, H, None]
        target, vcmd = goal[2], 0
        if self.vertical:
            vc = states[:, VCMD] if states.shape[1] > VCMD else 0
            vcmd = vertical_command(vc, actions)
            target = self.height_targets(vcmd, goal[2])[:, None]
        hs = h0 + clip(target - h0, self._sink(duration, n), body.rise)
        end = self._end(xy[:, -1], hs[:, -1], states[:, PSI], body)
        end[:, VCMD] = vcmd
        return body, xy, hs, end

    def height_targets(self, vcmd: np.ndarray, goal_h: float) -> np.ndarray:
        """(B,) the height targets of vertical commands ``vcmd`` (B,):
        :meth:`PlannerConfig.height_target`, vectorised."""
        up, down = (self.config.height_target(m, goal_h) for m in (1, -1))
        return np.where(vcmd > 0, up, np.where(vcmd < 0, down, goal_h))

    def _check(self, duration: float, track: Track) -> int:
        n = self.substeps(duration)
        if track.n != n:
            raise ValueError(
                f"the intruder track has {track.n} sub-steps, a {duration} s segment has {n}"
            )
        return n

    def _own_step(self, body: _BodyMotion, dt: float) -> float:
        """Longest 3-D straight piece of the ownship's sampled path (over the ground)."""
        return math.hypot(body.step_max + abs(self._wind) * dt, self.config.climb_rate_mps * dt)

    def _sink(self, duration: float, n: int) -> np.ndarray:
        """(n+1,) the most the ownship can have sunk by each sub-step instant (negative)."""
        return -self.config.climb_rate_mps * (duration / n) * np.arange(n + 1)

    def _near_goal(self, box: _Cylinder, goal: np.ndarray) -> bool:
        """Could a path inside ``box`` come within the tree's goal radius (``goal_aim_m``)?"""
        x, y, h, r_xy, r_h = box
        return math.dist((x, y, h), goal) <= math.hypot(r_xy, r_h) + self.config.goal_aim_m

    def _near_wall(self, box: _Cylinder) -> bool:
        """Could a path inside ``box`` leave the flight area?"""
        cfg = self.config
        x, y, h, r_xy, r_h = box
        return not (
            cfg.x_bounds[0] <= x - r_xy
            and x + r_xy <= cfg.x_bounds[1]
            and cfg.y_bounds[0] <= y - r_xy
            and y + r_xy <= cfg.y_bounds[1]
            and cfg.h_bounds[0] <= h - r_h
            and h + r_h <= cfg.h_bounds[1]
        )

    def _body(self, v0, phi0, cmd0, actions, duration: float, n: int) -> _BodyMotion:
        """The body motion of a batch of rows (one circle bounds them all), memoised by the
        exact bits of its inputs: a world that flies the same aircraft step after step asks
        the same batch again and again (straight and level at a steady speed), and gets the
        very numbers it computed the first time."""
        args = [np.asarray(a, dtype=float) for a in (v0, phi0, cmd0)]
        actions = np.asarray(actions)
        if args[0].size * (n + 1) > _BATCH_CELLS:  # a search's batch: seldom asked again
            return self._bodies(*args, actions, duration, n, 1, memo=False)[0]
        key = (*(a.tobytes() for a in args), actions.tobytes(), actions.dtype.str, duration, n)
        body = self._batches.get(key)
        if body is None:
            if len(self._batches) >= _BATCH_MEMO:
                self._batches.clear()
            body = self._batches[key] = self._bodies(
                *args, actions, duration, n, 1, memo=False
            )[0]
        return body

    def _bodies(
        self, v0, phi0, cmd0, actions, duration: float, n: int, groups: int, memo: bool = True
    ) -> list[_BodyMotion]:
        """The body motions of ``groups`` equal consecutive groups of rows, computed in one
        batch: every number is computed per row, so a group's motion is the same as if it
        had been computed alone (the memo's answer never depends on its batch). ``memo``:
        with what a search needs of a memoised motion (``table``, ``children``)."""
        cfg = self.config
        dt = duration / n
        tm = dt * (np.arange(n) + 0.5)  # sub-step midpoints
        roll = self._roll
        phi_cmd = bank_command(cmd0, actions, cfg)
        accel = accel_command(actions, cfg)
        band = self._band or cfg.speed_mps
        vmin = np.minimum(band[0], v0)  # an out-of-range start speed never jumps
        vmax = np.maximum(band[1], v0)

        dphi = (phi_cmd - phi0)[:, None]
        phi_m = phi0[:, None] + clip(dphi, -roll * tm, roll * tm)
        v_m = clip(v0[:, None] + accel[:, None] * tm, vmin[:, None], vmax[:, None])
        # Coordinated turn: on each sub-step the rate is taken at its midpoint and the
        # displacement is the exact chord of that constant-rate arc.
        dpsi = turn_rate_of_bank(phi_m, v_m) * dt
        psi = np.cumsum(dpsi, axis=1)
        chord = v_m * dt * np.sinc(dpsi / (2.0 * np.pi))
        rel_heading = psi - 0.5 * dpsi  # mid-sub-step heading relative to the start
        z = np.zeros((len(v0), n + 1), dtype=complex)
        np.cumsum(chord * np.exp(1j * (0.5 * np.pi - rel_heading)), axis=1, out=z[:, 1:])

        # End values land exactly on the command / limit once reached, so lattice states
        # (and their memo keys) repeat.
        roll_reach = roll * duration
        phi_end = np.where(
            np.abs(dphi[:, 0]) <= roll_reach, phi_cmd, phi0 + np.sign(dphi[:, 0]) * roll_reach
        )
        v_end = clip(v0 + accel * duration, vmin, vmax)
        rise = np.zeros((len(v0), n + 1))  # the climb at each sub-step's midpoint speed
        np.cumsum(climb_rate(v_m, cfg) * dt, axis=1, out=rise[:, 1:])
        template = np.zeros((len(v0), STATE_DIM))
        template[:, V], template[:, PHI], template[:, PHI_CMD] = v_end, phi_end, phi_cmd
        # What only a search asks of a memoised motion is left out of a world's step.
        rows, rise_end, table, kids = [()] * len(v0), [()] * len(v0), None, [()] * len(v0)
        ball, ball_r = [0j] * groups, [0.0] * groups
        size = len(v0) // groups
        if memo:
            rows, rise_end, table, kids, ball, ball_r = _search_extras(
                z, psi[:, -1], rise[:, -1], v_end, phi_end, phi_cmd, groups, duration
            )
        step_max = chord.reshape(groups, -1).max(axis=1).tolist()  # the longest chord
        z_end = z[:, -1].copy()
        out = []
        for g in range(groups):
            part = slice(g * size, (g + 1) * size)
            out.append(
                _BodyMotion(
                    z=z[part],
                    dpsi=psi[part, -1],
                    v_end=v_end[part],
                    phi_end=phi_end[part],
                    phi_cmd=phi_cmd[part],
                    ball=ball[g],
                    ball_r=ball_r[g],
                    step_max=step_max[g],
                    template=template[part],
                    z_end=z_end[part],
                    rows=tuple(rows[part]),
                    rise=rise[part],
                    rise_end=tuple(rise_end[part]),
                    table=None if table is None else table[part],
                    children=tuple(kids[part]),
                )
            )
        return out

    def _end(self, xy_end, h_end, psi, body: _BodyMotion) -> np.ndarray:
        end = body.template.copy()
        end[:, X] = xy_end.real
        end[:, Y] = xy_end.imag
        end[:, H] = h_end
        end[:, PSI] = np.mod(psi + body.dpsi, 2.0 * np.pi)
        return end

    # -------------------------------------------------------------------------------- events
    def _intruder_hits(
        self,
        xy: np.ndarray,
        hs: np.ndarray,
        seen: _Intruders,
        own_step: float,
        exact: bool,
        never: np.ndarray,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
        """First conflicting sub-step per branch (``never`` if none), squared separations, and
        the fraction along each sub-step of the closest point (None: ``sep2`` is per instant).

        Squared distances at the sub-step instants first. No point of a sub-step's relative
        chord is farther than half its length from an end, so if every sampled distance clears
        d_min by that much there is no conflict, and the sampled minimum is within L^2 / (8 d)
        of the true one; otherwise solve every chord. With the conflict cylinder
        (``PlannerConfig.cylinder_aspect``) "distance" is its norm ``max(|r_xy|, aspect
        |r_h|)``, below ``d_min`` exactly inside it; a chord is at most ``max(1, aspect)``
        times longer in it.
        """
        cfg = self.config
        aspect = cfg.cylinder_aspect
        k_hit, frac = never, None
        rel_xy = xy[:, :, None] - seen.xy  # (B, n+1, k)
        rel_h = hs[:, :, None] - seen.h  # (B or 1, n+1, k)
        sep2 = rel_xy.real**2
        sep2 += rel_xy.imag**2
        slack = 0.5 * (own_step + seen.step_max) + 1e-6
        if aspect is None:
            sep2 += rel_h**2
        else:
            rel_h = aspect * rel_h
            sep2 = np.maximum(sep2, rel_h**2)
            slack = max(1.0, aspect) * (slack - 1e-6) + 1e-6
        margin = seen.margin
        if margin is None:
            close = sep2.min() < (cfg.d_min_m + slack) ** 2
        else:
            # A sub-step needs its end's (larger) margin all along, so each instant is
            # held to the larger of its own and the next one's.
            ahead = np.concatenate([margin[:, 1:], margin[:, -1:]], axis=1)
            close = (np.sqrt(sep2) - np.maximum(margin, ahead)).min() < cfg.d_min_m + slack
        if exact or close:
            if aspect is None:
                sep2, frac = _closest_on_chords(rel_xy, rel_h, sep2)  # (B, n, k) per sub-step
            else:
                d_xy, d_h = np.diff(rel_xy, axis=1), np.diff(rel_h, axis=1)
                sep2, frac = cylinder_closest(rel_xy.real[:, :-1], rel_xy.imag[:, :-1],
                                              rel_h[:, :-1], d_xy.real, d_xy.imag, d_h)  # fmt: skip
            if margin is None:
                k_hit = _first_true(sep2.min(axis=2) < cfg.d_min_m**2)
            else:
                # The margin grows with time: a sub-step needs its end's.
                need = cfg.d_min_m + margin[:, 1:]
                k_hit = _first_true((sep2 < need**2).any(axis=2))
        return k_hit, sep2, frac

    def _events(
        self,
        end: np.ndarray | None,
        xy: np.ndarray,
        hs: np.ndarray,
        goal: np.ndarray,
        seen: _Intruders | None,
        box: _Cylinder,
        dt: float,
        own_step: float,
        exact: bool,
    ) -> Segment:
        cfg = self.config
        B, n = xy.shape[0], xy.shape[1] - 1
        rows = np.arange(B)
        never = np.full(B, n)
        k = 0 if seen is None else seen.ids.size

        # Intruders: cheap sampled distances first, exact chords only near a conflict.
        k_hit, sep2, frac = never, None, None
        if seen is not None and k:
            k_hit, sep2, frac = self._intruder_hits(xy, hs, seen, own_step, exact, never)

        k_out = never
        if self._near_wall(box):
            # The box is convex: a chord between two samples inside it stays inside.
            h_all = np.broadcast_to(hs, xy.shape)[:, 1:]
            outside = (
                (xy.real[:, 1:] < cfg.x_bounds[0])
                | (xy.real[:, 1:] > cfg.x_bounds[1])
                | (xy.imag[:, 1:] < cfg.y_bounds[0])
                | (xy.imag[:, 1:] > cfg.y_bounds[1])
                | (h_all < cfg.h_bounds[0])
                | (h_all > cfg.h_bounds[1])
            )
            k_out = _first_true(outside)
        k_goal = never
        if self._near_goal(box, goal):
            g_xy = xy - complex(goal[0], goal[1])
            g_h = np.broadcast_to(hs - goal[2], xy.shape)
            g_d2, _ = _closest_on_chords(g_xy, g_h, g_xy.real**2 + g_xy.imag**2 + g_h**2)
            k_goal = _first_true(g_d2 < cfg.goal_aim_m**2)

        # The first event wins; at equal sub-steps collision beats leaving the map beats the
        # goal (the conservative reading of a sub-step that holds two of them).
        if k_out is never and k_goal is never:  # the usual case in a search: skip the sort
            k_event = k_hit
            happened = k_event < n
            event = np.where(happened, COLLISION, NONE).astype(np.int8)
        else:
            first = np.stack([k_hit, k_out, k_goal])
            kind = np.argmin(first, axis=0)
            k_event = first[kind, rows]
            happened = k_event < n
            event = np.where(happened, _EVENT_CODES[kind], NONE).astype(np.int8)
        t_event = np.where(happened, k_event * dt, np.nan)
        if sep2 is None:
            return Segment(
                end, np.full(B, np.inf), np.full(B, -1), np.zeros(B), event, t_event, xy, hs
            )

        min_sep, closest, t_closest = _closest_approach(sep2, frac, seen, k_event, happened, dt)
        return Segment(
            end=end,
            min_sep=min_sep,
            closest=closest,
            t_closest=t_closest,
            event=event,
            t_event=t_event,
            xy=xy,
            hs=hs,
        )


def _search_extras(z, dpsi, rise_end, v_end, phi_end, phi_cmd, groups: int, duration: float):
    """What a tree search asks of memoised body motions (rows ``z`` (B, n+1), the others
    (B,)): per row its end in plain Python numbers, its rise, its table row (the compiled
    search's) and its children's memo keys; per group of rows the circle holding its paths."""
    rows = list(zip(z[:, -1].tolist(), dpsi.tolist(), v_end.tolist(), phi_end.tolist(),
                    phi_cmd.tolist(), strict=True))  # fmt: skip
    table = np.stack([z[:, -1].real, z[:, -1].imag, dpsi, v_end, phi_end, phi_cmd, rise_end],
                     axis=1)  # fmt: skip
    kids = motion_keys(v_end, phi_end, phi_cmd, duration)
    zg = z.reshape(groups, -1)
    lo = zg.real.min(axis=1) + 1j * zg.imag.min(axis=1)
    hi = zg.real.max(axis=1) + 1j * zg.imag.max(axis=1)
    centre = 0.5 * (lo + hi)
    ball_r = np.abs(zg - centre[:, None]).max(axis=1).tolist()
    return rows, rise_end.tolist(), table, kids, centre.tolist(), ball_r


def _closest_approach(
    sep2: np.ndarray,
    frac: np.ndarray | None,
    seen: _Intruders,
    k_event: np.ndarray,
    happened: np.ndarray,
    dt: float,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Per branch: the minimum separation (net of the margins, if any), the id of the intruder
    it is to, and its time, counting only up to the end of the sub-step of the first event.

    ``sep2`` is (B, n+1, k) per instant when ``frac`` is None, else (B, n, k) per sub-step with
    ``frac`` the closest point's fraction along it.
    """
    B, k = sep2.shape[0], seen.ids.size
    rows = np.arange(B)
    if happened.any():
        # Separation counts up to the end of the event's sub-step, not beyond.
        last = k_event + (1 if frac is None else 0)  # instants vs sub-steps
        after = np.arange(sep2.shape[1])[None, :] > last[:, None]
        sep2 = np.where(after[..., None], np.inf, sep2)
    if seen.margin is None:
        flat = sep2.reshape(B, -1).argmin(axis=1)
        k_min, j_min = np.divmod(flat, k)
        min_sep = np.sqrt(sep2[rows, k_min, j_min])
    else:
        # With margins the separation that counts is what is left if the intruder stands
        # its margin off its predicted track towards us (clipped at 0): below d_min
        # exactly when the line collides, so outcome and separation tell one story.
        m = seen.margin[:, 1:] if frac is not None else seen.margin
        gap = np.sqrt(sep2) - m
        flat = gap.reshape(B, -1).argmin(axis=1)
        k_min, j_min = np.divmod(flat, k)
        min_sep = np.maximum(gap[rows, k_min, j_min], 0.0)
    t_closest = k_min * dt if frac is None else (k_min + frac[rows, k_min, j_min]) * dt
    return min_sep, seen.ids[j_min], t_closest


def _closest_on_chords(
    rel_xy: np.ndarray, rel_h: np.ndarray, d2: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Squared closest distance, and its fraction ``s`` in [0, 1], on every sub-step.

    ``rel_xy`` (complex) and ``rel_h`` hold relative positions at the sub-step instants
    (axis 1), ``d2`` their squared norms; within a sub-step the relative motion is linear.
    """
    dxy = np.diff(rel_xy, axis=1)
    dh = np.diff(rel_h, axis=1)
    a = dxy.real**2 + dxy.imag**2 + dh**2
    b = (rel_xy[:, :-1].conj() * dxy).real + rel_h[:, :-1] * dh
    s = clip(-b / np.maximum(a, 1e-12), 0.0, 1.0)
    # |r0 + s dr|^2 = |r0|^2 + s (2 b + s a), never below 0 despite rounding
    return np.maximum(d2[:, :-1] + s * (2.0 * b + s * a), 0.0), s


def _first_true(mask: np.ndarray) -> np.ndarray:
    """Index of the first True along axis 1, or the axis length when there is none."""
    return np.where(mask.any(axis=1), mask.argmax(axis=1), mask.shape[1])


# ------------------------------------------------------------------------------ model drift
def model_drift(
    config: PlannerConfig,
    flown: Sequence[Ownship],
    actions: Sequence[int],
    goal: np.ndarray,
    horizons: Sequence[int],
    every: int = 1,
) -> dict[int, np.ndarray]:
    """How far an aircraft strayed from this model: from every ``every``-th decision k of a
    flight (``flown[k]`` the ownship then, ``actions[k]`` the action chosen), the model flies
    the actions actually chosen, one decision period each, open loop; per horizon n (in
    decisions) the horizontal distances between its position and ``flown[k + n]``, m. The
    evidence behind ``PlannerConfig.own_error_10s_m`` (benchmarks/studies/bench_own_model.py)."""
    period = config.decision_period_s
    last = max(horizons)
    out: dict[int, list[float]] = {n: [] for n in horizons}
    model = EncounterModel(config)
    alone = Track.of(np.zeros((model.substeps(period) + 1, 0, 3)))  # the ownship's path only
    for k in range(0, len(flown) - last, every):
        model.carry_ownship(ownship_air(flown[k], config))
        state = ownship_state(flown[k])[None]
        for n in range(1, last + 1):
            action = np.array([actions[k + n - 1]])
            seg = model.fly(state, action, goal, period, alone, cull=False, exact=True)
            state = seg.end
            if n in out:
                truth = flown[k + n]
                out[n].append(float(np.hypot(state[0, 0] - truth.x, state[0, 1] - truth.y)))
    return {n: np.asarray(d) for n, d in out.items()}
