"""A route layer above the tree (issue 31's "room to manoeuvre"): each decision, a coarse
route through the predicted traffic toward the goal, whose first waypoint the tree steers for.

Why: the tree looks ``depth x action_hold_s`` (16 s) ahead and scores a clear line by its goal
distance alone, so in a crowded sky it threads between two intruders toward the goal and, a
few decisions later, finds itself boxed in by them and the area's edges (docs/results: among
40 random-turn intruders `mcts_vertical` times out in 0.31 of the episodes and leaves the area
in 0.125). The route looks further (``ROUTE_HORIZON_S``) and more coarsely: ``HEADINGS`` legs
from the ownship at its speed, each followed by a straight line to the goal, scored by the
time to the goal along them plus a cost for every intruder predicted (straight, as the
alerting stage predicts) within ``ROUTE_CLEAR_FACTOR x d_min`` of the leg, and ruled out when
the leg leaves the area. The tree then plans for the leg's end as its goal, with everything
else as before: the waypoint is a direction, the tree still does the avoiding. When the goal
is nearer than a leg, or the straight line to it is clear, the goal is the goal.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from uavxai.avoidance.mcts import intruder_arrays
from uavxai.avoidance.types import Decision, Goal, Intruder, Ownship
from uavxai.geometry import wrap_angle

ROUTE_HORIZON_S = 30.0  # one leg's flight time, s: twice the tree's reach
HEADINGS = 16  # legs every 22.5 deg around the ownship
ROUTE_CLEAR_FACTOR = 2.0  # a leg passing within this many d_min of a track pays for it
CONFLICT_COST_S = 60.0  # what a leg's conflict costs, in seconds of flight to the goal
SAMPLES = 16  # points along a leg where separation is predicted


def _legs(own: Ownship, n: int, horizon_s: float) -> tuple[np.ndarray, np.ndarray]:
    """(n,) headings and (n, SAMPLES, 2) positions along each leg (every horizon / SAMPLES)."""
    psi = own.heading + 2.0 * math.pi * np.arange(n) / n
    t = horizon_s * np.arange(1, SAMPLES + 1) / SAMPLES
    d = own.speed * t
    xy = np.stack([own.x + np.sin(psi)[:, None] * d, own.y + np.cos(psi)[:, None] * d], axis=-1)
    return psi, xy


def leg_costs(
    own: Ownship, intruders: Sequence[Intruder], goal: Goal, cfg, xy: np.ndarray | None = None
) -> np.ndarray:
    """(HEADINGS,) cost of each leg in seconds: flight time to the goal through the leg's end,
    a conflict cost per intruder predicted too near, infinity for a leg leaving the area.
    ``xy``: the legs' positions when the caller has them (:func:`_legs`)."""
    if xy is None:
        _, xy = _legs(own, HEADINGS, ROUTE_HORIZON_S)
    end = xy[:, -1]
    speed = max(own.speed, 1.0)
    cost = ROUTE_HORIZON_S + np.hypot(goal[0] - end[:, 0], goal[1] - end[:, 1]) / speed
    x, y = xy[..., 0], xy[..., 1]
    out = ((x < cfg.x_bounds[0]) | (x > cfg.x_bounds[1])
           | (y < cfg.y_bounds[0]) | (y > cfg.y_bounds[1])).any(axis=1)  # fmt: skip
    cost[out] = np.inf
    if intruders:
        pos, vel = intruder_arrays(intruders)
        t = ROUTE_HORIZON_S * np.arange(1, SAMPLES + 1) / SAMPLES
        at = pos[:, None, :2] + vel[:, None, :2] * t[None, :, None]  # (N, S, 2)
        near_h = np.abs(pos[:, 2] + vel[:, 2] * ROUTE_HORIZON_S / 2 - own.h) < cfg.d_min_m * 2
        gap = np.linalg.norm(xy[:, None, :, :] - at[None, :, :, :], axis=-1).min(axis=2)  # (H, N)
        clear = ROUTE_CLEAR_FACTOR * cfg.d_min_m
        cost += CONFLICT_COST_S * (((gap < clear) & near_h[None, :]).sum(axis=1))
    return cost


def route_goal(own: Ownship, intruders: Sequence[Intruder], goal: Goal, cfg) -> Goal:
    """The tree's goal this decision: the goal itself when it is within a leg or the route
    through the best leg is no better than the straight one, else the best leg's end."""
    speed = max(own.speed, 1.0)
    if math.hypot(goal[0] - own.x, goal[1] - own.y) <= speed * ROUTE_HORIZON_S:
        return goal
    psi, xy = _legs(own, HEADINGS, ROUTE_HORIZON_S)
    cost = leg_costs(own, intruders, goal, cfg, xy)
    best = int(np.argmin(cost))
    to_goal = math.atan2(goal[0] - own.x, goal[1] - own.y)
    straight = int(np.argmin(np.abs(wrap_angle(psi - to_goal))))
    if not np.isfinite(cost[best]) or cost[straight] <= cost[best]:
        return goal
    return (float(xy[best, -1, 0]), float(xy[best, -1, 1]), float(goal[2]))


class RoutedPlanner:
    """A tree planner steering for the route's waypoint (module docstring). Same seed, same
    inputs: same decision."""

    def __init__(self, inner, *, name: str) -> None:
        self.inner = inner
        self.config = inner.config
        self.name = name

    def reset(self, seed: int) -> None:
        self.inner.reset(seed)

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        waypoint = route_goal(own, intruders, goal, self.config)
        decision = self.inner.plan(own, intruders, waypoint, step=step)
        decision.planner = self.name
        return decision
