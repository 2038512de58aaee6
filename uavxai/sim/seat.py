"""The planner's seat in the episode engine: what the engine needs of whatever decides.

Three kinds sit there: an avoidance planner in the simulation's process (:class:`InProcess`,
``uavxai evaluate``), one on a companion process (:class:`uavxai.sim.companion.Companion`,
``uavxai run``), which may also decode and track the traffic beside it (its ``receiver``),
and a Gymnasium agent, whose actions a planner-shaped adapter turns into decisions
(``uavxai.learning.env``, in an :class:`InProcess` seat). The engine
(:class:`uavxai.sim.episode.Episode`) calls the seat's methods and reads its declared
attributes; it never asks what sits there.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Sequence
from typing import TYPE_CHECKING, Protocol

from uavxai.avoidance.types import Decision, Goal, Intruder, Ownship, Planner, PlannerConfig

if TYPE_CHECKING:
    from uavxai.surveillance.adsb import Report


class TrafficReceiver(Protocol):
    """The companion computer's side of surveillance (:class:`uavxai.sim.picture.Receiver`, in
    this process or on the companion's): frames and detections in, beliefs out."""

    def receive(self, frames: bytes, onboard: Sequence[Report], t: float) -> None: ...
    def beliefs(self, t: float) -> list[Intruder]: ...


class Seat(ABC):
    """Whatever decides, as the engine uses it: :meth:`submit` the picture at t, then
    :meth:`result` the decision (at once, or a latency later: the engine flies on between)."""

    name: str  # the planner's name, as summaries and explanations give it
    config: PlannerConfig
    # The receiver that decodes and tracks the traffic beside the planner, so that it can
    # plan from its own picture (:meth:`submit_onboard`); None: the simulation's picture.
    receiver: TrafficReceiver | None = None
    # True: it plans on another core, so the world flies the intruders through the period
    # ahead while it searches (nothing they do depends on the command being searched for).
    parallel: bool = False
    # The picture the last :meth:`submit_onboard` planned from, once :meth:`result` returned.
    beliefs: list[Intruder]

    @abstractmethod
    def reset(self, seed: int) -> None:
        """Re-seed whatever randomness the planner uses: same seed, same decisions."""

    @abstractmethod
    def submit(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> None:
        """Plan from ``intruders`` (``step``: :class:`~uavxai.avoidance.types.Planner`'s);
        :meth:`result` returns the decision."""

    @abstractmethod
    def result(self) -> Decision:
        """The decision of the last submit, waiting for it if it is still being planned."""

    def submit_onboard(self, own: Ownship, t: float, goal: Goal, *, step: int = 0) -> None:
        """Plan from the :attr:`receiver`'s own beliefs at ``t``; :meth:`result` returns the
        decision and :attr:`beliefs` the picture. Only a seat with a receiver offers it."""
        raise NotImplementedError(f"{type(self).__name__} has no receiver beside its planner")


class InProcess(Seat):
    """A planner in the simulation's process: it plans when submitted to, on this core."""

    def __init__(self, planner: Planner) -> None:
        self.planner = planner
        self._decision: Decision | None = None

    @property
    def name(self) -> str:  # type: ignore[override]  # the planner's, whenever asked
        return self.planner.name

    @property
    def config(self) -> PlannerConfig:  # type: ignore[override]
        return self.planner.config

    def reset(self, seed: int) -> None:
        self.planner.reset(seed)

    def submit(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> None:
        self._decision = self.planner.plan(own, intruders, goal, step=step)

    def result(self) -> Decision:
        decision, self._decision = self._decision, None
        if decision is None:
            raise RuntimeError("result() without a submit() before it")
        return decision


def seat_of(planner: Planner | Seat) -> Seat:
    """``planner`` in its seat: a :class:`Seat` as it is, any other planner in-process."""
    return planner if isinstance(planner, Seat) else InProcess(planner)
