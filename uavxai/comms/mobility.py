"""Ground users that walk: ``comms.users.mobility`` (``static`` | ``random_waypoint``).

Random waypoint (Johnson & Maltz 1996; Camp, Boleng & Davies 2002): each user walks in a
straight line to a waypoint drawn uniformly in ``comms.users.region`` at a speed drawn uniformly
in ``speed_mps``, pauses there for a time drawn uniformly in ``pause_s``, then draws the next
waypoint and speed. Users start walking at t = 0 towards their first waypoint. A user placed
outside the region (explicit ``comms.users.positions`` need not lie inside it) walks into it
and, the region being a rectangle, never leaves it again.

Seeding. Every user has its own random stream (``SeedSequence.spawn``), consumed only when
that user reaches a waypoint. A user's path therefore depends on the seed alone: not on the
step ``dt`` of :meth:`UserMobility.advance`, nor on how many other users there are, so a run
logged at 10 Hz and a check at 1 Hz see the same walkers. ``static`` users never move and draw
nothing.

``speed_mps`` and ``pause_s`` are ``[min, max]`` ranges drawn uniformly per leg, or one number
for a fixed value (the classic model's constant pause). Without the key, walking speeds default
to 0.5-1.5 m/s (pedestrians: Bohannon 1997 measured 1.3-1.5 m/s
comfortable gait; the lower end covers strolling) and pauses to 0-30 s.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Any

import numpy as np

from uavxai.comms.channel import draw_users
from uavxai.errors import UserError
from uavxai.scenario import Mobility, Scenario

MOBILITY_MODELS = ("static", "random_waypoint")
_DEFAULT = Mobility()  # the schema's defaults (comms.users.mobility), declared there once

# Mixed into the scenario seed so that the walkers' streams are not the stream that placed the
# users (draw_users uses default_rng(seed)) nor any other consumer of the bare seed.
MOBILITY_STREAM = 0x6D6F62  # "mob"

# A leg or a pause ends at most once per user per pass of advance(); a dt spanning more legs
# than this (hours of walking in one call) is a caller bug, not a long walk.
_MAX_PASSES = 100_000

SeedLike = int | Sequence[int] | np.random.SeedSequence | np.random.Generator | None


def _bounds(value: Any, name: str, lowest: float, strict: bool) -> tuple[float, float]:
    """``[min, max]``, or one number for a fixed value (the schema's scalar form)."""
    try:
        lo, hi = (float(value),) * 2 if np.ndim(value) == 0 else (float(v) for v in value)
    except (TypeError, ValueError):
        raise UserError(
            f"comms.users.mobility.{name} must be a number or [min, max], got {value!r}"
        ) from None
    ok_lo = lo > lowest if strict else lo >= lowest
    if not (np.isfinite(lo) and np.isfinite(hi) and ok_lo and lo <= hi):
        bound = f"> {lowest:g}" if strict else f">= {lowest:g}"
        hint = " (model: static is for users who stand still)" if strict else ""
        raise UserError(
            f"comms.users.mobility.{name} must be a number or [min, max], finite, with min "
            f"{bound} and min <= max; got [{lo}, {hi}]{hint}"
        )
    return lo, hi


def _region(region: Any) -> tuple[np.ndarray, np.ndarray]:
    """(lo, hi) corners ``(2,)`` from a Region model, a ``{x: [..], y: [..]}`` mapping, or
    ``((x0, x1), (y0, y1))``."""
    if isinstance(region, Mapping):
        xs, ys = region["x"], region["y"]
    elif hasattr(region, "x") and hasattr(region, "y"):
        xs, ys = region.x, region.y
    else:
        xs, ys = region
    lo = np.array([float(xs[0]), float(ys[0])])
    hi = np.array([float(xs[1]), float(ys[1])])
    if not (np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)) and np.all(lo < hi)):
        raise UserError(
            f"comms.users.region must have x and y as [min, max] with min < max, got "
            f"x {list(xs)}, y {list(ys)}"
        )
    return lo, hi


class UserMobility:
    """K ground users moving under ``model``; :attr:`positions` is ``(K, 3)`` with h = 0.

    ``seed`` may be an int, a sequence of ints, a ``SeedSequence`` or a ``Generator`` (a
    generator is used only to derive the per-user streams, once, at construction).
    """

    def __init__(
        self,
        users_xy: np.ndarray,
        region: Any,
        model: str = _DEFAULT.model,
        speed_mps: float | Sequence[float] = _DEFAULT.speed_mps,
        pause_s: float | Sequence[float] = _DEFAULT.pause_s,
        seed: SeedLike = None,
    ) -> None:
        if model not in MOBILITY_MODELS:
            raise UserError(
                f"comms.users.mobility.model '{model}' is unknown; allowed: "
                f"{', '.join(MOBILITY_MODELS)}"
            )
        xy = np.asarray(users_xy, dtype=float)
        if xy.ndim != 2 or xy.shape[1] not in (2, 3) or len(xy) == 0:
            raise UserError(f"user positions must be (K, 2) or (K, 3), got shape {xy.shape}")
        if not np.all(np.isfinite(xy)):
            raise UserError("user positions must be finite numbers")
        self.model = model
        # Static users never read speed or pause: a 0 m/s in the file is not an error then.
        walking = model == "random_waypoint"
        self.speed_mps = _bounds(speed_mps, "speed_mps", 0.0, strict=walking)
        self.pause_s = _bounds(pause_s, "pause_s", 0.0, strict=False)
        self.region_lo, self.region_hi = _region(region)
        self.t = 0.0
        self._xy = xy[:, :2].copy()
        k = len(xy)
        if isinstance(seed, np.random.Generator):
            seed = np.random.SeedSequence(seed.integers(0, 2**63, size=4).tolist())
        elif not isinstance(seed, np.random.SeedSequence):
            seed = np.random.SeedSequence(seed)
        self._rngs = [np.random.default_rng(s) for s in seed.spawn(k)]
        self._target = self._xy.copy()
        self._speed = np.zeros(k)
        self._pause_left = np.zeros(k)
        if model == "random_waypoint":
            for i in range(k):
                self._target[i], self._speed[i] = self._next_leg(i)

    # ------------------------------------------------------------------ construction
    @classmethod
    def from_scenario(
        cls, scenario: Scenario, users: np.ndarray | None = None, seed: SeedLike = None
    ) -> UserMobility:
        """From ``comms.users`` (``mobility: {model, speed_mps, pause_s}``, all optional:
        a scenario without the key gets static users). ``users`` defaults to
        ``channel.draw_users(scenario)``; ``seed`` to ``[scenario.seed, MOBILITY_STREAM]``."""
        users_cfg = scenario.comms.users
        config = users_cfg.mobility
        if users is None:
            users = draw_users(scenario)
        if seed is None:
            seed = [int(scenario.seed), MOBILITY_STREAM]
        return cls(
            users,
            users_cfg.region,
            model=config.model,
            speed_mps=config.speed_mps,
            pause_s=config.pause_s,
            seed=seed,
        )

    # ------------------------------------------------------------------ state
    @property
    def k(self) -> int:
        return len(self._xy)

    @property
    def moving(self) -> bool:
        """False for ``static``: the users' positions are constant, callers may cache."""
        return self.model != "static"

    @property
    def positions(self) -> np.ndarray:
        """``(K, 3)``, h = 0 (a copy)."""
        return np.column_stack([self._xy, np.zeros(self.k)])

    @property
    def paused(self) -> np.ndarray:
        """``(K,)`` bool: the user is standing at a waypoint (always True for ``static``)."""
        return (self._pause_left > 0) | (self._speed == 0)

    @property
    def velocities(self) -> np.ndarray:
        """``(K, 3)`` m/s: the current walking velocity (zero while paused)."""
        delta = self._target - self._xy
        dist = np.linalg.norm(delta, axis=1)
        walking = ~self.paused & (dist > 0)
        v = np.zeros((self.k, 3))
        v[walking, :2] = delta[walking] / dist[walking, None] * self._speed[walking, None]
        return v

    @property
    def waypoints(self) -> np.ndarray:
        """``(K, 2)``: where each user is walking to (its position when static)."""
        return self._target.copy()

    # ------------------------------------------------------------------ motion
    def _next_leg(self, i: int) -> tuple[np.ndarray, float]:
        rng = self._rngs[i]
        target = rng.uniform(self.region_lo, self.region_hi)
        return target, float(rng.uniform(*self.speed_mps))

    def advance(self, dt: float) -> np.ndarray:
        """Walk every user for ``dt`` seconds (exactly: legs and pauses that end inside the
        interval are chained within it); returns :attr:`positions`."""
        dt = float(dt)
        if not (np.isfinite(dt) and dt >= 0):
            raise UserError(f"mobility time step must be a finite number >= 0 s, got {dt}")
        self.t += dt
        if self.model == "static" or dt == 0:
            return self.positions
        remaining = np.full(self.k, dt)
        for _ in range(_MAX_PASSES):
            # Pausing users use up their pause (or the whole interval).
            pausing = (remaining > 0) & (self._pause_left > 0)
            used = np.minimum(self._pause_left[pausing], remaining[pausing])
            self._pause_left[pausing] -= used
            remaining[pausing] -= used
            walking = (remaining > 0) & (self._pause_left <= 0)
            if not walking.any():
                break
            delta = self._target - self._xy
            dist = np.linalg.norm(delta, axis=1)
            time_to_go = dist / self._speed
            arrive = walking & (time_to_go <= remaining)
            en_route = walking & ~arrive
            step = (self._speed * remaining)[en_route] / dist[en_route]
            self._xy[en_route] += delta[en_route] * step[:, None]
            remaining[en_route] = 0.0
            # Arrivals: stand at the waypoint, then pause and pick the next leg. Only the
            # arriving users draw, each from its own stream, so paths do not depend on dt.
            self._xy[arrive] = self._target[arrive]
            remaining[arrive] -= time_to_go[arrive]
            for i in np.flatnonzero(arrive):
                self._pause_left[i] = self._rngs[i].uniform(*self.pause_s)
                self._target[i], self._speed[i] = self._next_leg(i)
        else:  # pragma: no cover - only with absurd dt against a tiny region
            raise UserError(f"mobility time step {dt} s spans too many waypoints; use smaller")
        return self.positions

    def path(self, dt: float, steps: int) -> np.ndarray:
        """Positions ``(steps + 1, K, 3)`` at t, t + dt, ..., t + steps dt (advancing self)."""
        out = np.empty((steps + 1, self.k, 3))
        out[0] = self.positions
        for n in range(1, steps + 1):
            out[n] = self.advance(dt)
        return out
