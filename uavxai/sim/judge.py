"""One judge for every episode: the outcome rules, applied after every sample.

Order matters and is fixed: a dynamics failure first (nothing after it is physics), then a
collision (the closest approach between two samples, both aircraft moving linearly, so a
pass-through between samples counts), then leaving the flight area, then the goal.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from uavxai.dynamics.state import TrafficState
from uavxai.geometry import closest_approach
from uavxai.metrics import NMAC_HORIZONTAL_M, NMAC_VERTICAL_M, nmac
from uavxai.scenario import Scenario, World
from uavxai.vocabulary import Outcome


class Judge:
    def __init__(
        self,
        world: World,
        d_min_m: float,
        goal: Sequence[float] | None,
        goal_radius_m: float,
        nmac_m: tuple[float, float] = (NMAC_HORIZONTAL_M, NMAC_VERTICAL_M),
    ) -> None:
        self.world = world
        self.d_min_m = d_min_m
        self.goal = None if goal is None else np.asarray(goal, dtype=float)
        self.goal_radius_m = goal_radius_m
        self.nmac_m = nmac_m

    @classmethod
    def from_scenario(cls, scenario: Scenario, goal: Sequence[float] | None) -> Judge:
        """The scenario's rules: its flight area, ``avoidance.d_min_m`` and ``goal_radius_m``,
        and its NMAC cylinder (``avoidance.nmac``, 500 ft x 100 ft by default); ``goal`` None:
        no goal ends the episode (a mission's)."""
        av = scenario.avoidance
        nmac_m = (float(av.nmac.horizontal_m), float(av.nmac.vertical_m))
        return cls(scenario.world, av.d_min_m, goal, av.goal_radius_m, nmac_m=nmac_m)

    def nmac(
        self, prev: TrafficState, now: TrafficState, separation_m: float | None = None
    ) -> bool:
        """Did any intruder come inside the NMAC cylinder between two samples (both moving
        linearly, :func:`uavxai.metrics.nmac`)? ``separation_m``, the closest approach over
        the same samples (:meth:`separation`), if known: beyond the cylinder's corner nobody
        can be inside it, and most samples end there without solving the cylinder."""
        h, v = self.nmac_m
        if separation_m is not None and separation_m > math.hypot(h, v):
            return False
        if now.n < 2 or prev.ids != now.ids:
            prev = now  # a replaced row: judge the newcomer where it is
        own = np.stack([prev.pos[0], now.pos[0]])
        intruders = np.stack([prev.pos[1:], now.pos[1:]])
        return bool(nmac(own, intruders, *self.nmac_m).any()) if now.n > 1 else False

    def separation(self, prev: TrafficState, now: TrafficState) -> float:
        """Smallest ownship-intruder distance between two samples (inf without intruders).
        A row whose aircraft was replaced in between (persistent traffic) counts from now."""
        if now.n < 2 or prev.n != now.n:
            return now.min_separation()
        if prev.ids == now.ids:
            return closest_approach(prev.pos[0], now.pos[0], prev.pos[1:], now.pos[1:])
        same = np.array([a == b for a, b in zip(prev.ids[1:], now.ids[1:], strict=True)])
        new = now.pos[1:][~same]
        fresh = float(np.min(np.linalg.norm(new - now.pos[0], axis=1))) if len(new) else math.inf
        kept = closest_approach(prev.pos[0], now.pos[0], prev.pos[1:][same], now.pos[1:][same])
        return min(kept, fresh)

    def judge(self, now: TrafficState, flown_min_m: float, failure: str | None) -> Outcome | None:
        """The outcome the episode ends with after this sample, or None to go on."""
        if failure:
            return Outcome.FDM_FAILURE
        if flown_min_m < self.d_min_m:
            return Outcome.COLLISION
        x, y, h = (float(v) for v in now.pos[0])
        if not self.world.contains(x, y, h):
            return Outcome.OUT_OF_BOUNDS
        if self.goal is not None and math.dist((x, y, h), self.goal) < self.goal_radius_m:
            return Outcome.GOAL
        return None
