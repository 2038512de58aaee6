"""The alerting stage in front of a tree search: quiet flight until traffic threatens well clear.

Detect-and-avoid systems (DO-365's DAIDALUS, ACAS X) do not manoeuvre for every aircraft in
sight: an **alert** is raised when an intruder is predicted to come inside well clear within an
alerting time (DO-365 Phase I: 55 s preventive / corrective, 25 s warning), and only an alerted
system guides the aircraft away. Without it the tree planners re-plan against every track at
every decision, which the pairwise encounter campaigns (docs/daa-metrics.md) count as
manoeuvres in encounters that would have stayed clear anyway, and which costs a search each
second.

:class:`AlertingPlanner` wraps a tree planner. At each decision it projects the ownship and
every track along straight lines (state-based, as DAIDALUS does) for ``alert_horizon_s``,
sampled every ``ALERT_STEP_S``, with the small-UAS well-clear cylinder (``alert_well_clear_m``,
2000 ft / 250 ft) widened by ``uncertainty_k`` sigmas of the track's position error as it grows
(``sigma_m + sigma_v t``). No intruder inside: the decision is the nominal one (the `none`
planner's, steering for the goal at the leg's height), said as "clear of traffic". An intruder
inside: the tree decides. An alert lasts at least ``alert_hold_s`` after its last threat, so
that the ownship does not turn back into a conflict the moment the prediction clears.

While alerted, the tree keeps the route's action whenever the route's line has no conflict and
has had none for ``alert_hold_s``, whatever the visits prefer: a detect-and-avoid system leaves
its route only to avoid, and the search's preferences among conflict-free lines are no reason to
manoeuvre. The hold is hysteresis: a line that grazes the conflict distance, in conflict one
second and clear the next, would otherwise rock the wings. A quiet spell ends the count (the
ownship is back on its route by then).
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uavxai.avoidance.direct import DirectPlanner, route_action
from uavxai.avoidance.mcts import height_command, intruder_arrays
from uavxai.avoidance.types import Decision, Goal, Intruder, Ownship, check_plan_inputs

ALERT_STEP_S = 0.5  # at 110 m/s of closure, 55 m per sample against a 610 m cylinder
HOLD_SPEED_ACTION = 4  # bank hold, speed hold: what `none` flies when it keeps its heading


@dataclass(frozen=True)
class Threat:
    """An intruder predicted inside the (widened) well-clear cylinder within the horizon."""

    id: int | str
    t_enter_s: float  # first predicted time inside, s from now
    hmd_m: float  # least predicted horizontal distance over the horizon
    radius_m: float  # the widened horizontal radius at entry


def threats(
    own: Ownship,
    intruders: Sequence[Intruder],
    horizon_s: float,
    well_clear_m: tuple[float, float],
    k: float,
) -> list[Threat]:
    """The intruders predicted inside well clear within ``horizon_s``, soonest first."""
    if not intruders:
        return []
    pos, vel = intruder_arrays(intruders)
    ground = own.ground_velocity or (own.speed * math.sin(own.heading),
                                     own.speed * math.cos(own.heading))  # fmt: skip
    own_v = np.array([ground[0], ground[1], 0.0])  # level: a climb ends at its height target
    t = np.arange(0.0, horizon_s + 1e-9, ALERT_STEP_S)
    rel = (pos - np.array([own.x, own.y, own.h]))[:, None, :] + (vel - own_v)[:, None, :] * t[
        None, :, None
    ]
    sigma = np.array([[i.sigma_m, i.sigma_v] for i in intruders], dtype=float)
    radius = well_clear_m[0] + k * (sigma[:, :1] + sigma[:, 1:] * t[None, :])
    horizontal = np.hypot(rel[..., 0], rel[..., 1])
    inside = (horizontal <= radius) & (np.abs(rel[..., 2]) <= well_clear_m[1])
    out: list[Threat] = []
    for i in np.flatnonzero(inside.any(axis=1)):
        j = int(np.argmax(inside[i]))
        out.append(Threat(intruders[i].id, float(t[j]), float(horizontal[i].min()),
                          float(radius[i, j])))  # fmt: skip
    return sorted(out, key=lambda th: th.t_enter_s)


class AlertingPlanner:
    """A tree planner behind an alerting stage (module docstring). Same seed, same inputs:
    same decision."""

    def __init__(self, inner, *, name: str) -> None:
        self.inner = inner
        self.config = inner.config
        self.name = name
        self.nominal = DirectPlanner(self.config, name=name)
        self._last_threat_t: float | None = None  # decision time of the last threat, s
        self._t = -math.inf  # this decision's time, s (counted here: ``step`` restarts per leg)
        self._route_clear_s = math.inf  # how long the route's line has been clear, s

    def reset(self, seed: int) -> None:
        self.inner.reset(seed)
        self._last_threat_t = None
        self._t = -math.inf
        self._route_clear_s = math.inf

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        t0 = time.perf_counter()
        check_plan_inputs(own, intruders, goal)
        cfg = self.config
        self._t = 0.0 if self._t == -math.inf else self._t + cfg.decision_period_s
        now = self._t
        found = threats(own, intruders, cfg.alert_horizon_s, cfg.alert_well_clear_m,
                        cfg.uncertainty_k)  # fmt: skip
        if found:
            self._last_threat_t = now
        held = self._last_threat_t is not None and now - self._last_threat_t < cfg.alert_hold_s
        if found or held:
            return self._avoid(own, intruders, goal, step)
        self._route_clear_s = math.inf
        decision = self.nominal.plan(own, intruders, goal, step=step)
        decision.alt_target_m = height_command(
            self.inner.model, HOLD_SPEED_ACTION, own, np.asarray(goal, dtype=float)
        )
        decision.words = (_quiet_words(own, intruders, goal, cfg), "")
        decision.ms = 1000.0 * (time.perf_counter() - t0)
        return decision

    def _avoid(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, step: int
    ) -> Decision:
        """The tree's decision, keeping the route while its line has been clear for the hold
        (module docstring)."""
        cfg = self.config
        route = route_action(own, goal, cfg)
        keep = route if self._route_clear_s >= cfg.alert_hold_s else None
        decision = self.inner.plan(own, intruders, goal, step=step, keep=keep)
        line = next((c for c in decision.children if c.action == route), None)
        clear = line is not None and line.clear
        self._route_clear_s = self._route_clear_s + cfg.decision_period_s if clear else 0.0
        decision.planner = self.name
        return decision


def _quiet_words(own: Ownship, intruders: Sequence[Intruder], goal: Goal, cfg) -> str:
    """Why no avoidance: nothing predicted inside well clear within the alerting time."""
    h, v = cfg.alert_well_clear_m
    said = (f"clear of traffic: no intruder predicted within {h:.0f} m and {v:.0f} m of "
            f"height in the next {cfg.alert_horizon_s:.0f} s; steering for the goal "
            f"({math.dist((own.x, own.y, own.h), goal):.0f} m away)")  # fmt: skip
    if intruders:
        near = min(intruders, key=lambda i: math.dist((i.x, i.y, i.h), (own.x, own.y, own.h)))
        d = math.dist((near.x, near.y, near.h), (own.x, own.y, own.h))
        said += f"; nearest intruder {near.id} at {d:.0f} m"
    return said
