"""The simulation clock, counted in whole integrator ticks.

Samples (trajectory rows, telemetry, collision checks) and decisions fire on multiples of the
tick, so a decision period of 1 s is exactly 1 s of flight whatever the rates; a rate that
does not divide is refused rather than rounded (a 100 Hz integrator with 30 Hz samples would
decide every 0.9 s while the planner assumes 1 s).
"""

from __future__ import annotations

from dataclasses import dataclass

from uavxai.errors import UserError
from uavxai.scenario import Scenario, clock_ticks


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
        """The clock of ``scenario``, by the schema's rule (:func:`clock_ticks`); a scenario
        built past the schema's checks (``model_copy``) is refused here with its message."""
        try:
            sample, decision, lag = clock_ticks(scenario.dynamics, scenario.avoidance)
        except ValueError as exc:
            raise UserError(f"{exc}; see docs/scenario.md") from None
        return cls(rate_hz=scenario.dynamics.rate_hz, sample_ticks=sample,
                   decision_ticks=decision, latency_ticks=lag)  # fmt: skip

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
