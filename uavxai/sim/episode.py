"""One episode: decide -> advance (sample by sample, judged) -> ... -> finish.

The engine knows nothing of files, recordings or ground stations: what acts on an episode
beside the planner (the picture, the operator, the mission, the battery, the service) is an
:class:`EngineStep` with a declared place in the loop, and everything that only watches is an
:class:`Observer`; both are subscribed to its events (start, decision, sample, period, end),
the steps first, in their order, then the observers, whose order changes nothing. The dynamics
(JSBSim or kinematic) and the command path (MAVLink bytes or direct) are arguments, so ``uavxai
run`` and ``uavxai evaluate`` fly the same loop, and the same scenario and seed give the same
flight through either path.
"""

from __future__ import annotations

import dataclasses
import math
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Protocol

import numpy as np

from uavxai.avoidance.types import Decision, Intruder, Ownship
from uavxai.dynamics.protocol import Dynamics
from uavxai.dynamics.state import TrafficState
from uavxai.processes import interrupts_deferred
from uavxai.sim.clock import Clock
from uavxai.sim.command import CommandPath
from uavxai.sim.judge import Judge
from uavxai.sim.seat import Seat, TrafficReceiver
from uavxai.surveillance.tracker import truth_beliefs
from uavxai.vocabulary import Outcome


def ownship_view(state: TrafficState, bank_cmd: float, vertical: int = 0) -> Ownship:
    """The ownship as the planner sees it: its own navigation state (with its ground
    velocity), bank command and vertical command (the vertical action set's)."""
    return Ownship(
        x=float(state.pos[0, 0]),
        y=float(state.pos[0, 1]),
        h=float(state.pos[0, 2]),
        speed=float(state.airspeed[0]),
        heading=float(state.att[0, 2]),
        bank=float(bank_cmd),
        phi=float(state.att[0, 0]),
        vertical=int(vertical),
        ground_velocity=(float(state.vel[0, 0]), float(state.vel[0, 1])),
    )


class TrafficPicture(Protocol):
    """What the engine needs of the planner's picture of the traffic
    (:class:`uavxai.sim.picture.Picture`, or :data:`TRUTH`)."""

    receiver: TrafficReceiver | None  # where its beliefs are formed (None: nowhere: exact)
    truth: bool  # every intruder's exact state (no surveillance model)

    def __call__(self, state: TrafficState) -> list[Intruder]: ...


class _Truth:
    """Every intruder's exact state, the paper's setting (:func:`truth_beliefs`)."""

    receiver = None
    truth = True

    def __call__(self, state: TrafficState) -> list[Intruder]:
        return truth_beliefs(state)


TRUTH: TrafficPicture = _Truth()


@dataclass
class _Pending:
    """A decision on its way to the autopilot: the step and picture it was planned from
    (``onboard``: the picture is the seat's own, it comes back with the decision)."""

    step: int
    t: float
    own: Ownship
    intruders: list[Intruder]
    truth: TrafficState
    onboard: bool = False


@dataclass
class DecisionEvent:
    step: int
    t: float
    own: Ownship
    intruders: list[Intruder]
    decision: Decision
    truth: TrafficState
    applied_t: float | None = None  # when the command reached the autopilot (None: at t)


@dataclass
class EpisodeResult:
    outcome: Outcome
    steps: int
    flight_time_s: float
    min_separation_m: float
    decision_ms: list[float]
    wall_s: float
    nmac: bool = False
    failure: str | None = None
    summary: dict = field(default_factory=dict)


class Observer:
    """Subscribe to an episode's events; every method is optional. ``close`` is always
    called, also when the episode is interrupted, so files end whole.

    An observer only observes: it reads the episode (and what its steps hold) and writes its
    own outputs and its own summary section; it commands nothing, changes nothing another
    reads, and reads no other observer's section, so the observers' order changes nothing
    (``tests/test_sim_observer_order.py``). What acts is an :class:`EngineStep`."""

    def on_start(self, ep: Episode) -> None: ...
    def on_decision(self, ep: Episode, event: DecisionEvent) -> None: ...
    def on_sample(self, ep: Episode, state: TrafficState) -> None: ...
    def on_period(self, ep: Episode, event: DecisionEvent, flown_min_m: float) -> None: ...
    def on_end(self, ep: Episode, summary: dict) -> None: ...
    def close(self) -> None: ...


class EngineStep(Observer):
    """A step of the engine that acts on the episode beside the planner: it commands the path,
    changes the mission, moves the station, ends the mission. The episode calls its steps at
    every event before any observer, in the order it was given them; that order is declared
    once, by :func:`uavxai.sim.build.fly`: the picture (surveillance), the scripted and the
    live operator, the mission's phases, then the run's own steps in their order (``uavxai
    run``: the battery, which turns the mission home at its reserve and ends it empty, then
    the service, which re-plans and moves the station). A step may read an earlier step's
    summary section (the service adds to the mission's)."""


class Episode:
    """An episode of ``world`` flown by the planner in ``seat`` through ``path`` towards
    ``goal``."""

    def __init__(
        self,
        world: Dynamics,
        seat: Seat,
        path: CommandPath,
        judge: Judge,
        clock: Clock,
        *,
        goal: Sequence[float],
        max_steps: int,
        observers: Sequence[Observer] = (),
        picture: TrafficPicture = TRUTH,
        label: dict | None = None,
        mission=None,
        engine_steps: Sequence[EngineStep] = (),
    ) -> None:
        self.world = world
        self.seat = seat
        self.path = path
        self.judge = judge
        self.clock = clock
        self.goal = tuple(float(g) for g in goal)
        self.max_steps = max_steps
        acting = [type(o).__name__ for o in observers if isinstance(o, EngineStep)]
        if acting:  # a step among the observers would act at a place nobody declared
            raise TypeError(
                f"{', '.join(acting)} act on the episode: give them as engine_steps, in their "
                "order, not as observers"
            )
        self.engine_steps = list(engine_steps)
        self.observers = list(observers)
        self._subscribers = [*self.engine_steps, *self.observers]  # the steps first, in order
        self.picture = picture
        self.mission = mission  # uavxai.sim.mission.Mission, or None: transit to `goal` only
        self.label = dict(label or {})  # scenario, seed, ...: the head of the summary
        self.state = world.state()
        self.steps = 0
        self.min_separation_m = self.state.min_separation()
        self.sample_separation_m = self.min_separation_m  # closest approach over the last sample
        self.decision_ms: list[float] = []
        self.sample_metrics: dict = {}  # per-sample values observers share (rates, users)
        self.operator = None  # uavxai.sim.operator.Operator, when a ground station may command
        self._pending: _Pending | None = None  # a decision on its way to the autopilot
        self.nmac = False  # any near mid-air collision (the judge's cylinder) so far
        self.wall0 = time.perf_counter()

    # ---------------------------------------------------------------------------- phases
    def decide(self) -> DecisionEvent | None:
        """Plan from what the ownship knows now and send the command; with a decision
        latency the planner's command is only sent (and the event only raised) when it
        reaches the autopilot, in :meth:`advance` (None here)."""
        state = self.state
        own = self.ownship()
        plan = self.plan()
        goal = self.aim()
        if self._plan_onboard(state, own, goal):
            self._fly_intruders_ahead()  # while the companion searches
            if self.clock.latency_ticks:
                return None
            return self._arrive(send=True, latency=False)
        intruders = self.picture(state)
        decision = plan.decide(self, own, intruders) if plan is not None else None
        if decision is None and self.clock.latency_ticks:
            # in-process: planned now, applied later; a companion: planning meanwhile
            self._start_search(own, intruders, goal)
            self._pending = _Pending(self.steps, state.t, own, intruders, state)
            self.steps += 1
            return None
        if decision is None:  # the avoidance planner flies
            decision = self._search(own, intruders, goal)
            self.path.send(decision, state.t)
        self.steps += 1
        event = DecisionEvent(self.steps - 1, state.t, own, intruders, decision, state)
        return self._decided(event)

    def _plan_onboard(self, state: TrafficState, own: Ownship, goal) -> bool:
        """A companion that also tracks the traffic plans from its own picture of it: one
        round trip fewer per decision, the same beliefs (they come back with the decision,
        :meth:`_arrive`). Only where nothing else needs the picture before the planner."""
        onboard = self.seat.receiver
        if (
            onboard is None
            or self.plan() is not None
            or self.picture.receiver is not onboard
            or self.picture.truth
        ):
            return False
        self.seat.submit_onboard(own, state.t, goal, step=self._budget_step())
        self._pending = _Pending(self.steps, state.t, own, [], state, onboard=True)
        self.steps += 1
        return True

    def _search(self, own: Ownship, intruders: list[Intruder], goal) -> Decision:
        """The planner's decision now."""
        self._start_search(own, intruders, goal)
        return self.seat.result()

    def _start_search(self, own: Ownship, intruders: list[Intruder], goal) -> None:
        """Submit the picture to the seat; one that plans on another core searches while
        the world flies the intruders through the period ahead."""
        self.seat.submit(own, intruders, goal, step=self._budget_step())
        if self.seat.parallel:
            self._fly_intruders_ahead()

    def _fly_intruders_ahead(self) -> None:
        """Nothing the intruders do before the next decision depends on the command being
        searched for: the world may fly them meanwhile (JSBSim; the same flight to the bit)."""
        self.world.lookahead(self.clock.decision_ticks, self.clock.sample_ticks)

    def plan(self):
        """What the planner flies for now (a mission, an operator's route: something with a
        ``goal``, ``decide`` and ``outcome``), or None: ``goal``."""
        return self.operator.active(self) if self.operator is not None else self.mission

    def aim(self) -> tuple[float, float, float]:
        """Where the avoidance planner steers now."""
        plan = self.plan()
        if plan is not None:
            return plan.goal
        h = self.operator.height_m if self.operator is not None else None
        return self.goal if h is None else (self.goal[0], self.goal[1], h)

    def plan_label(self) -> str:
        """Who flies now, as the explanations name it: the mission's phase or the mode."""
        route = self.operator.route if self.operator is not None else None
        if route is not None:
            return route.label
        m = self.mission
        return m.phase.value.replace("_", " ") if m is not None else "transit"

    def _decided(self, event: DecisionEvent) -> DecisionEvent:
        if self.operator is not None and event.decision.words is None:
            event.decision.aim = self.operator.aim_words(self, event.t)
        self.decision_ms.append(event.decision.ms)
        for o in self._subscribers:
            o.on_decision(self, event)
        return event

    def _arrive(self, send: bool, latency: bool = True) -> DecisionEvent:
        """The pending decision reaches the autopilot now (``send``), or the episode ended
        before it did: it is still recorded, as the planner made it. Without a ``latency``
        it is applied at the picture's time, as an in-process decision."""
        p, self._pending = self._pending, None
        decision = self.seat.result()
        intruders = self.seat.beliefs if p.onboard else p.intruders  # what it planned from
        if send:
            self.path.send(decision, self.state.t)
        applied = self.state.t if latency else None
        event = DecisionEvent(p.step, p.t, p.own, intruders, decision, p.truth, applied)
        return self._decided(event)

    def ownship(self) -> Ownship:
        """The ownship as the planner sees it now (:func:`ownship_view` of the autopilot's
        commands)."""
        cmd = self.world.ownship_command()
        vertical = self.seat.config.vertical_of(cmd.get("alt_target_m"))
        own = ownship_view(self.state, cmd["bank_cmd_rad"], vertical)
        cruise = self.path.cruise_speed(None)
        if cruise is not None:  # the operator's airspeed, a ceiling the planner may slow below
            lo = min(self.seat.config.speed_mps[0], cruise)
            own = dataclasses.replace(own, speed_band=(lo, cruise))
        return own

    def _budget_step(self) -> int:
        """The ``step`` the planner weighs its time-out against: it sees one coming
        ``config.max_steps - step`` decisions ahead, and the time-out that can happen is this
        episode's (``self.max_steps``: a mission's covers transit, station and return
        together, not one leg), so the step passed makes that count the decisions this
        episode has left (issue 30: a leg's count had on-station searches value their lines
        against a time-out 700 decisions too early). Without a mission the episode's limit is
        the planner's own ``max_steps``, or an encounter's observation window, which ends the
        flight without being a deadline the ownship must beat: the planner counts its own."""
        if self.mission is None:
            return self.steps
        return self.seat.config.max_steps - (self.max_steps - self.steps)

    def advance(self, event: DecisionEvent | None) -> Outcome | None:
        """Fly one decision period sample by sample, judging each; the outcome or None.
        A pending decision (``event`` None) is applied after the latency's samples."""
        flown_min, outcome = math.inf, None
        for k in range(self.clock.samples_per_decision):
            if self._pending is not None and k == self.clock.latency_samples:
                event = self._arrive(send=True)
            self.world.step(self.clock.sample_ticks)
            sep, outcome = self.sample()
            flown_min = min(flown_min, sep)
            if outcome is not None:
                break
        if self._pending is not None:
            event = self._arrive(send=False)
        for o in self._subscribers:
            o.on_period(self, event, flown_min)
        return outcome

    def begin(self) -> None:
        """Tell the subscribers the episode starts (:meth:`run` does; a fleet member's
        episode is begun by the fleet)."""
        for o in self._subscribers:
            o.on_start(self)

    def sample(self) -> tuple[float, Outcome | None]:
        """The world has flown a sample: read it, judge it, tell every subscriber; the
        closest approach over the sample and the outcome (None: flying on). A fleet member's
        episode is handed its samples this way by the fleet (``uavxai.sim.fleet``)."""
        prev = self.state
        self.state = self.world.state()
        self.path.on_sample(self.state)
        sep = self.judge.separation(prev, self.state)
        self.sample_separation_m = sep  # observers read it rather than judge again
        self.nmac = self.nmac or self.judge.nmac(prev, self.state, sep)
        self.min_separation_m = min(self.min_separation_m, sep)
        for o in self._subscribers:
            o.on_sample(self, self.state)
        outcome = self.judge.judge(self.state, sep, self.world.failure())
        if outcome is None:
            plan = self.plan()
            outcome = plan.outcome if plan is not None else None
        if outcome is None and self.mission is not None:
            outcome = self.mission.outcome  # the battery ends a suspended mission too
        return sep, outcome

    def run(self) -> EpisodeResult:
        """Fly to the end; observers are closed whatever happens. A signal (SIGINT, SIGTERM)
        ends the flight as ``interrupted``; while the episode is then saved (its summary,
        the observers' files) signals wait, so the files end whole: one that comes then is
        raised after the save (``KeyboardInterrupt``), unless the episode is already
        interrupted."""
        outcome: Outcome = Outcome.TIMEOUT
        try:
            self.begin()
            self.wall0 = time.perf_counter()  # the flight starts now: set-up is not counted
            try:
                while self.steps < self.max_steps:
                    ended = self.advance(self.decide())
                    if ended is not None:
                        outcome = ended
                        break
            except KeyboardInterrupt:
                outcome = Outcome.INTERRUPTED
        except BaseException:
            with interrupts_deferred():
                self._close_observers()
            raise
        with interrupts_deferred(deliver=outcome is not Outcome.INTERRUPTED):
            try:
                return self.finish(outcome)
            finally:
                self._close_observers()

    def _close_observers(self) -> None:
        for o in self._subscribers:
            o.close()

    def finish(self, outcome: Outcome) -> EpisodeResult:
        wall = time.perf_counter() - self.wall0
        failure = self.world.failure()
        sep = self.min_separation_m
        summary = {
            **self.label,
            "outcome": outcome.value,
            "min_separation_m": sep if math.isfinite(sep) else None,
            "nmac": self.nmac,
            "steps": self.steps,
            "flight_time_s": round(self.state.t, 3),
            "goal": list(self.goal),
            "decision_ms": stats(self.decision_ms),
            "sim_realtime_factor": self.state.t / wall if wall > 0 else None,
            "avoidance_planner": self.seat.name,
            "intruders": self.state.n - 1,
        }
        # always present (README's summary fields): null and [] when nothing failed
        summary["failure"] = failure or None
        summary["intruders_lost"] = list(self.world.lost_intruders)  # failed in flight, replaced
        counters = self.path.close()
        if counters is not None:
            summary["bridge"] = counters
        for o in self._subscribers:
            o.on_end(self, summary)
        return EpisodeResult(
            outcome=outcome,
            steps=self.steps,
            flight_time_s=self.state.t,
            min_separation_m=sep,
            decision_ms=self.decision_ms,
            wall_s=wall,
            nmac=self.nmac,
            failure=failure,
            summary=summary,
        )


def stats(values: Sequence[float], keys=("mean", "p50", "p95", "max")) -> dict:
    """Mean, median, 95th percentile and maximum (None for no values)."""
    if not len(values):
        return dict.fromkeys(keys)
    a = np.asarray(values, dtype=float)
    table = {
        "mean": float(a.mean()),
        "p50": float(np.percentile(a, 50)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }
    return {k: table[k] for k in keys}
