"""A fleet's encounters, member with member and member with intruder (docs/fleet.md, "Fleet
campaigns"): ``summary.fleet_encounters``, written by every fleet run and read by a fleet
campaign's row.

Every sample, each member is measured against every other member and every intruder by the
judge's own rules, along the judge's own pieces since the last sample
(:func:`uavxai.sim.judge.pieces_since_last_sample`: both moving linearly, so a pass-through
between samples counts; a pair one of whose rows was replaced in between, persistent traffic,
counts from now, the other pairs keep their piece): the closest approach
(:func:`uavxai.geometry.closest_approaches`) and the NMAC cylinder (``avoidance.nmac``,
:func:`uavxai.metrics.nmac`). Counts are of distinct pairs (a pair inside the cylinder for a
minute is one NMAC), by the aircraft's ids: a replaced intruder is another aircraft.
"""

from __future__ import annotations

import math

import numpy as np

from uavxai.dynamics.state import TrafficState, is_member
from uavxai.geometry import closest_approaches
from uavxai.metrics import nmac
from uavxai.scenario import Scenario
from uavxai.sim.episode import Episode, Observer
from uavxai.sim.judge import pieces_since_last_sample


class FleetEncounters(Observer):
    """Member-member and member-intruder closest approaches, NMACs and collisions (a closest
    approach below ``avoidance.d_min_m``, the judge's collision) over a fleet's flight."""

    def __init__(self, d_min_m: float, nmac_m: tuple[float, float]) -> None:
        self.d_min_m, self.nmac_m = float(d_min_m), nmac_m
        self._prev: TrafficState | None = None
        self.closest_members_m = math.inf
        self.closest_intruder_m = math.inf
        self.member_nmacs: set[tuple[str, str]] = set()
        self.intruder_nmacs: set[tuple[str, str]] = set()
        self.member_collisions: set[tuple[str, str]] = set()
        self.intruder_collisions: set[tuple[str, str]] = set()

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> FleetEncounters:
        """The scenario's rules: ``avoidance.d_min_m`` and its NMAC cylinder, as the judge's."""
        av = scenario.avoidance
        return cls(av.d_min_m, (float(av.nmac.horizontal_m), float(av.nmac.vertical_m)))

    def on_start(self, ep: Episode) -> None:
        self._prev = ep.state  # the first sample is measured from the start, as the judge's

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        prev = self._prev if self._prev is not None else state
        self._prev = state
        ids = state.ids
        members = [i for i, who in enumerate(ids) if is_member(who)]
        traffic = [i for i, who in enumerate(ids) if not is_member(who)]
        for n, m in enumerate(members):
            self._pairs(prev, state, m, members[n + 1 :], member=True)
            self._pairs(prev, state, m, traffic, member=False)

    def _pairs(self, prev: TrafficState, now: TrafficState, m: int, others: list[int],
               member: bool) -> None:  # fmt: skip
        if not others:
            return
        own, them = pieces_since_last_sample(prev, now, m, others)
        dist = closest_approaches(own[0], own[1], them[0], them[1])
        dist = np.where(np.isnan(dist), np.inf, dist)  # a row not present (NaN) meets no one
        if member:
            self.closest_members_m = min(self.closest_members_m, float(dist.min()))
        else:
            self.closest_intruder_m = min(self.closest_intruder_m, float(dist.min()))
        near = dist < math.hypot(*self.nmac_m)  # beyond the cylinder's corner: not inside it
        inside = np.zeros(len(others), dtype=bool)
        if near.any():
            inside[near] = nmac(own[:, near], them[:, near], *self.nmac_m)
        for o, d, hit in zip(others, dist, inside, strict=True):
            pair = (now.ids[m], now.ids[o])
            if d < self.d_min_m:
                (self.member_collisions if member else self.intruder_collisions).add(pair)
            if hit:
                (self.member_nmacs if member else self.intruder_nmacs).add(pair)

    def section(self) -> dict:
        def metres(d: float) -> float | None:
            return round(d, 3) if math.isfinite(d) else None

        def pairs(found: set[tuple[str, str]]) -> list[list[str]]:
            return [list(p) for p in sorted(found)]

        return {
            "closest_members_m": metres(self.closest_members_m),
            "closest_intruder_m": metres(self.closest_intruder_m),
            "member_collisions": pairs(self.member_collisions),
            "intruder_collisions": pairs(self.intruder_collisions),
            "member_nmacs": pairs(self.member_nmacs),
            "intruder_nmacs": pairs(self.intruder_nmacs),
        }

    def on_end(self, ep: Episode, summary: dict) -> None:
        summary["fleet_encounters"] = self.section()
