"""Each episode's detect-and-avoid record (docs/daa-metrics.md, "In campaigns"): what the
field's metrics need of one flight, among one encounter's intruder or many random ones.

* ``hmd_m``, ``vmd_m``: :func:`uavxai.daa_metrics.hmd_vmd` of the flown ownship and the
  intruder that came closest horizontally, sampled at ``dynamics.trajectory_hz``;
* ``lowc``: :func:`uavxai.daa_metrics.loss_of_well_clear` with any intruder, with
  ``avoidance.well_clear``; ``nmac`` is the judge's (``avoidance.nmac``), as every campaign's;
* ``alert``: at some decision, the planner predicted a conflict on the line it would have
  flown toward the goal: the root option of the action the ``none`` planner takes in that
  state (same ownship, same picture, same goal) has a ``meets`` (its predicted line comes
  inside ``d_min_m`` plus the intruder's margin within the planner's look-ahead). A planner
  that reports no options (``none``) never alerts;
* ``manoeuvre``: at some decision, the command sent differs from what ``none`` would have sent
  in that state: another bank command (by more than 1e-6 rad), another acceleration as flown
  (a speed-up at the top speed, a slow-down at the bottom one, is none), or a height target
  more than 1 m off the leg's height. ``none`` never manoeuvres;
* ``reversals``: :func:`uavxai.daa_metrics.reversals` of the bank commands sent;
* ``weight``: the encounter's importance weight (1 for random traffic, every seed drawn from
  its own distribution).

The ownship's samples and bank commands are :class:`FlightQuality`'s (every campaign
episode's), which :class:`DaaObserver` reads rather than records again.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uavxai.avoidance import direct
from uavxai.avoidance.model import accel_command, bank_command
from uavxai.avoidance.types import PlannerConfig
from uavxai.daa_metrics import hmd_vmd, reversals
from uavxai.metrics import nmac
from uavxai.sim.episode import Episode, Observer
from uavxai.sim.flight_quality import FlightQuality

BANK_TOL_RAD = 1e-6
HEIGHT_TOL_M = 1.0


@dataclass
class DaaRecord:
    """One flight's detect-and-avoid columns (episodes.csv)."""

    weight: float
    hmd_m: float
    vmd_m: float
    lowc: bool
    alert: bool
    manoeuvre: bool
    reversals: int

    def columns(self) -> dict:
        """The record as its episodes.csv cells."""
        return {
            "weight": float(self.weight),
            "hmd_m": round(self.hmd_m, 3),
            "vmd_m": round(self.vmd_m, 3),
            "lowc": int(self.lowc),
            "alert": int(self.alert),
            "manoeuvre": int(self.manoeuvre),
            "reversals": int(self.reversals),
        }


class DaaObserver(Observer):
    """Records what the DAA columns need beyond the ownship's flight (``FlightQuality``'s): every
    intruder's position at every sample, and per decision whether the planner alerted and
    whether the command sent differs from what ``none`` would have sent in that state."""

    def __init__(self, config: PlannerConfig) -> None:
        self.config = config
        self.intruders: list[np.ndarray] = []  # per sample (n, 3); n may change (traffic flow)
        self.alert = False
        self.manoeuvre = False

    def _keep(self, state) -> None:
        self.intruders.append(state.pos[1:].copy())

    def on_start(self, ep: Episode) -> None:
        self._keep(ep.state)

    def on_sample(self, ep: Episode, state) -> None:
        self._keep(state)

    def on_decision(self, ep: Episode, event) -> None:
        d = event.decision
        if d.planner == direct.NAME:
            return  # the baseline neither alerts nor manoeuvres
        goal = ep.aim()
        base = direct.heading_action(event.own, goal, self.config)
        if not self.alert:
            child = next((c for c in d.children if c.action == base), None)
            self.alert = child is not None and child.meets is not None
        if not self.manoeuvre:
            cfg = self.config
            high = d.alt_target_m is not None and abs(d.alt_target_m - goal[2]) > HEIGHT_TOL_M
            accel = self._effective(event.own, d.accel_mps2)
            bank = float(bank_command(event.own.bank, base, cfg))
            base_accel = self._effective(event.own, float(accel_command(base, cfg)))
            self.manoeuvre = (abs(d.bank_cmd_rad - bank) > BANK_TOL_RAD
                              or abs(accel - base_accel) > 1e-9 or high)

    def _effective(self, own, accel: float) -> float:
        """An acceleration command as flown: none beyond the speed limits (a speed-up at the
        top speed holds the speed, as the autopilot's speed limits make it)."""
        lo, hi = own.speed_band or self.config.speed_mps
        if (accel > 0 and own.speed >= hi - 1e-6) or (accel < 0 and own.speed <= lo + 1e-6):
            return 0.0
        return float(accel)

    def tracks(self) -> np.ndarray:
        """(T, N, 3) the intruders' sampled positions, NaN where an intruder was absent (a
        sample with fewer aircraft than the most seen: the last ones are missing)."""
        n = max((len(p) for p in self.intruders), default=0)
        out = np.full((len(self.intruders), max(n, 1), 3), np.nan)
        for k, p in enumerate(self.intruders):
            out[k, : len(p)] = p
        return out

    def record(self, quality: FlightQuality, well_clear, weight: float = 1.0) -> DaaRecord:
        """The flight's record, with the ownship's samples from ``quality`` and the well-clear
        cylinder ``well_clear`` (the scenario's ``avoidance.well_clear``)."""
        own, intr = np.array(quality.own, dtype=float), self.tracks()
        miss = [hmd_vmd(own, intr[:, j]) for j in range(intr.shape[1])]
        hmd, vmd = min(miss, key=lambda m: m[0] if math.isfinite(m[0]) else math.inf)
        lowc = nmac(own, intr, well_clear.horizontal_m, well_clear.vertical_m)
        return DaaRecord(weight=float(weight), hmd_m=hmd, vmd_m=vmd, lowc=bool(lowc.any()),
                         alert=self.alert, manoeuvre=self.manoeuvre,
                         reversals=reversals(quality.bank_cmd))  # fmt: skip
