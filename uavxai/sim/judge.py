"""One judge for every episode: the outcome rules, applied after every sample.

Order matters and is fixed: a dynamics failure first (nothing after it is physics), then a
collision (the closest approach between two samples, both aircraft moving linearly, so a
pass-through between samples counts), then leaving the flight area, then the goal.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence

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
        if now.n < 2:
            return False
        own, intruders = pieces_since_last_sample(prev, now, 0, range(1, now.n))
        return bool(nmac(own, intruders, *self.nmac_m).any())

    def separation(self, prev: TrafficState, now: TrafficState) -> float:
        """Smallest ownship-intruder distance between two samples (inf without intruders),
        along :func:`pieces_since_last_sample` (a replaced row counts from now)."""
        if now.n < 2 or prev.n != now.n:
            return now.min_separation()
        own, intruders = pieces_since_last_sample(prev, now, 0, range(1, now.n))
        return closest_approach(own[0], own[1], intruders[0], intruders[1])

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


def pieces_since_last_sample(
    prev: TrafficState, now: TrafficState, m: int, others: Iterable[int]
) -> tuple[np.ndarray, np.ndarray]:
    """The pieces since the last sample along which row ``m`` is judged against each of rows
    ``others`` (the collision and NMAC tests of the judge and of a fleet's encounters): (own,
    them), each (2, k, 3), the two rows' positions at each piece's start and end (now).

    A pair whose two aircraft are those of the last sample starts there (both moving linearly
    in between: a pass-through no sample shows counts); a pair one of whose rows was replaced
    in between (persistent traffic; or the rows changed in number) starts now, where the
    newcomer is: it was not there before. The other pairs keep their piece."""
    rows = list(others)
    if prev.ids == now.ids:  # most samples: every pair keeps its piece
        same, start = np.ones(now.n, dtype=bool), prev
    elif prev.n == now.n:
        same, start = np.array([a == b for a, b in zip(prev.ids, now.ids, strict=True)]), prev
    else:
        same, start = np.zeros(now.n, dtype=bool), now
    kept = (same[rows] & same[m])[:, None]
    end_own = np.broadcast_to(now.pos[m], (len(rows), 3))
    own = np.stack([np.where(kept, start.pos[m], end_own), end_own])
    them = np.stack([np.where(kept, start.pos[rows], now.pos[rows]), now.pos[rows]])
    return own, them
