"""The simulation clock, counted in whole integrator ticks.

Samples (trajectory rows, telemetry, collision checks) and decisions fire on multiples of the
tick, so a decision period of 1 s is exactly 1 s of flight whatever the rates; a rate that
does not divide is refused rather than rounded (a 100 Hz integrator with 30 Hz samples would
decide every 0.9 s while the planner assumes 1 s).
"""

from __future__ import annotations

from dataclasses import dataclass

from uavxai.errors import UserError
from uavxai.scenario import Scenario

_TOL = 1e-6


def whole_ticks(seconds: float, tick_s: float, what: str) -> int:
    """``seconds`` as a whole number (>= 1) of ``tick_s``; UserError otherwise."""
    n = round(seconds / tick_s)
    if n < 1 or abs(n * tick_s - seconds) > _TOL * max(1.0, seconds):
        raise UserError(
            f"{what} = {seconds:g} s is not a whole number of {tick_s:g} s steps; choose rates "
            "that divide (e.g. dynamics.rate_hz 120, dynamics.trajectory_hz 10, "
            "avoidance.decision_period_s 1.0). See docs/scenario.md."
        )
    return n


@dataclass(frozen=True)
class Clock:
    rate_hz: float  # integrator ticks per simulated second
    sample_ticks: int  # ticks between samples (trajectory rows, telemetry, judging)
    decision_ticks: int  # ticks between decisions, a multiple of sample_ticks
    # ticks from a decision's picture to its command reaching the autopilot, a multiple of
    # sample_ticks below decision_ticks (0: at once)
    latency_ticks: int = 0

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> Clock:
        rate = scenario.dynamics.rate_hz
        tick = 1.0 / rate
        sample = whole_ticks(1.0 / scenario.dynamics.trajectory_hz, tick, "1 / trajectory_hz")
        decision = whole_ticks(
            scenario.avoidance.decision_period_s, tick, "avoidance.decision_period_s"
        )
        if decision % sample:
            raise UserError(
                f"avoidance.decision_period_s = {scenario.avoidance.decision_period_s:g} s is not "
                f"a whole number of trajectory samples (1 / {scenario.dynamics.trajectory_hz:g} "
                "s); see docs/scenario.md."
            )
        latency = scenario.avoidance.decision_latency_s
        lag = whole_ticks(latency, tick, "avoidance.decision_latency_s") if latency > 0 else 0
        if lag % sample or lag >= decision:
            raise UserError(
                f"avoidance.decision_latency_s = {latency:g} s must be a whole number of "
                "trajectory samples shorter than avoidance.decision_period_s; see "
                "docs/scenario.md."
            )
        return cls(rate_hz=rate, sample_ticks=sample, decision_ticks=decision, latency_ticks=lag)

    @property
    def dt(self) -> float:
        return 1.0 / self.rate_hz

    @property
    def sample_s(self) -> float:
        return self.sample_ticks / self.rate_hz

    @property
    def decision_s(self) -> float:
        return self.decision_ticks / self.rate_hz

    @property
    def samples_per_decision(self) -> int:
        return self.decision_ticks // self.sample_ticks

    @property
    def latency_samples(self) -> int:
        return self.latency_ticks // self.sample_ticks
