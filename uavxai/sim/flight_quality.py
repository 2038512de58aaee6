"""How well an episode was flown, beside whether it arrived (issue 31's flight-quality columns).

A safe avoidance can still fly badly: a long detour, a wing rocked left and right, steep bank
held for long. :class:`FlightQuality` watches an episode and gives, for ``episodes.csv``:

* ``path_excess``: the flown 3-D path length over the progress made along the straight route
  (start toward goal) by the episode's end, minus 1 (0 for a straight, level flight;
  :func:`path_excess_along`). NaN on a mission (its route is not a line) and when no progress
  was made. Not over an unequipped flight's length: an encounter lasts a fixed time, so two
  flights at the same speed have the same length whatever they did; the progress lost is the
  cost;
* ``reversals_per_min``: turn-direction reversals of the bank commands sent
  (:func:`uavxai.daa_metrics.reversals`) per minute of flight;
* ``bank_over_25_s``: time flown with the actual bank angle above 25 deg either way, s
  (FAA AC 120-71/ICAO call a bank above 25 deg steep for a transport; an operator's, and a
  passenger's, sense of a rough flight).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uavxai.daa_metrics import path_length, reversals
from uavxai.geometry import bearing
from uavxai.sim.episode import Episode, Observer

STEEP_BANK_DEG = 25.0
COLUMNS = ("path_excess", "reversals_per_min", "bank_over_25_s")


def path_excess_along(own: np.ndarray, start: np.ndarray, heading: float) -> float:
    """Flown 3-D path length over the progress along the route (start, heading) minus 1; nan
    when the ownship made no progress."""
    ahead = np.array([math.sin(heading), math.cos(heading)])
    progress = float((own[-1, :2] - start[:2]) @ ahead)
    return path_length(own) / progress - 1.0 if progress > 1e-6 else math.nan


@dataclass(frozen=True)
class Quality:
    path_excess: float
    reversals_per_min: float
    bank_over_25_s: float

    def row(self) -> dict[str, float]:
        """The ``episodes.csv`` cells (``COLUMNS``), rounded as the file keeps them."""
        return {k: round(float(getattr(self, k)), 4) for k in COLUMNS}  # its own fields


class FlightQuality(Observer):
    """Records the ownship's sampled positions and bank angles and the bank commands sent;
    ``route``: (start, goal) of a flight to a goal, None on a mission."""

    def __init__(self, route: tuple[Sequence[float], Sequence[float]] | None) -> None:
        self.route = route
        self.own: list[np.ndarray] = []
        self.t: list[float] = []
        self.phi: list[float] = []
        self.bank_cmd: list[float] = []

    def _keep(self, state) -> None:
        self.own.append(state.pos[0].copy())
        self.t.append(float(state.t))
        self.phi.append(float(state.att[0, 0]))

    def on_start(self, ep: Episode) -> None:
        self._keep(ep.state)

    def on_sample(self, ep: Episode, state) -> None:
        self._keep(state)

    def on_decision(self, ep: Episode, event) -> None:
        self.bank_cmd.append(float(event.decision.bank_cmd_rad))

    def result(self) -> Quality:
        own = np.array(self.own, dtype=float).reshape(-1, 3)
        t = np.array(self.t, dtype=float)
        minutes = (t[-1] - t[0]) / 60.0 if len(t) > 1 else 0.0
        excess = math.nan
        if self.route is not None and len(own) > 1:  # the start's route, not the planner's
            start, goal = (np.asarray(p, dtype=float) for p in self.route)
            excess = path_excess_along(own, start, bearing(*(goal - start)[:2]))
        # each sample's bank holds until the next one (the last one has no duration)
        steep = np.abs(np.degrees(np.array(self.phi[:-1]))) > STEEP_BANK_DEG
        per_min = reversals(self.bank_cmd) / minutes if minutes > 0 else math.nan
        return Quality(
            path_excess=excess,
            reversals_per_min=float(per_min),
            bank_over_25_s=float(np.diff(t)[steep].sum()) if len(t) > 1 else 0.0,
        )
