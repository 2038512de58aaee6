"""Flying an episode: the world (by dynamics name), the command path, the observers.

``fly`` is the one entry point behind ``uavxai run`` and both kinds of ``uavxai evaluate``;
each flies an :class:`uavxai.sim.spec.EpisodeSpec` (start, goal, intruders, step budget),
so what differs between them is only which dynamics, which command path and which observers.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass, field

import numpy as np

from uavxai.avoidance.types import Planner
from uavxai.dynamics.orbit import scenario_orbit_radius
from uavxai.dynamics.protocol import Dynamics
from uavxai.scenario import Scenario
from uavxai.sim.clock import Clock
from uavxai.sim.command import CommandPath, DirectPath
from uavxai.sim.episode import (
    TRUTH,
    EngineStep,
    Episode,
    EpisodeResult,
    Observer,
    TrafficPicture,
)
from uavxai.sim.judge import Judge
from uavxai.sim.kinematic import KinematicWorld
from uavxai.sim.mission import Mission
from uavxai.sim.operator import Operator, ScriptedOperator
from uavxai.sim.picture import Picture
from uavxai.sim.seat import Seat, seat_of
from uavxai.sim.spec import EpisodeSpec, episode_spec
from uavxai.vocabulary import DYNAMICS_MODELS


def _jsbsim(scenario: Scenario, intruders, seed: int, tracks=None) -> Dynamics:
    from uavxai.dynamics.world import JSBSimWorld  # jsbsim only when it flies

    return JSBSimWorld(scenario, intruders=intruders, seed=seed, tracks=tracks)


def _kinematic(scenario: Scenario, intruders, seed: int, tracks=None) -> Dynamics:
    return KinematicWorld(scenario, intruders=intruders, seed=seed, tracks=tracks)


# The dynamics by name: `uavxai evaluate --dynamics NAME`; called (scenario, intruders, seed,
# tracks), tracks an intruder index -> trajectory mapping or None.
DYNAMICS: dict[str, Callable[..., Dynamics]] = {
    "jsbsim": _jsbsim,
    "kinematic": _kinematic,
}
assert tuple(DYNAMICS) == DYNAMICS_MODELS, tuple(DYNAMICS)  # the names the CLI offers


def open_world(spec: EpisodeSpec) -> Dynamics:
    """The world of ``spec``: its dynamics with its intruders, seed and tracks."""
    return DYNAMICS[spec.dynamics](spec.scenario, list(spec.intruders), spec.seed, spec.tracks)


def fly(
    spec: EpisodeSpec,
    planner: Planner | Seat,
    *,
    path: Callable[[Dynamics], CommandPath] = DirectPath,
    observers: Sequence[Observer] = (),
    engine_steps: Sequence[EngineStep] = (),
) -> EpisodeResult:
    """Fly the episode ``spec`` (:func:`uavxai.sim.spec.episode_spec`) and return its result;
    the world is closed and every observer closed whatever happens. With a mission the
    episode flies it (transit, on station, return; the goal is then the service point)
    instead of ending at the goal. ``planner``: a planner (in-process) or the seat it sits in
    (:class:`uavxai.sim.companion.Companion`). ``engine_steps``: what acts beside the
    planner, after the episode's own steps, in this order: the engine's steps are the picture,
    the scripted operator, the operator and the mission (:class:`EngineStep`)."""
    scenario, seed = spec.scenario, spec.seed
    seat = seat_of(planner)
    world = command = None
    try:
        world = open_world(spec)
        seat.reset(seed)
        command = path(world)
        # a companion planner decodes and tracks the traffic on its own core, too
        picture = Picture(scenario, command.relay, seat.receiver)
        command.show_truth_traffic(picture.truth)  # ground stations see what the planner sees
        flying = Mission(spec.mission, command.announce) if spec.mission is not None else None
        start = spec.start
        operator = Operator(
            (start.x, start.y, start.h), scenario_orbit_radius(scenario), start.speed_mps
        )
        script = [ScriptedOperator(scenario)] if scenario.operator.commands else []
        episode = start_episode(
            scenario,
            world,
            seat,
            command,
            spec.goal,
            max_steps=spec.max_steps,
            observers=observers,
            # the declared order of what acts: surveillance, the operators' aims, the
            # mission's phases, then the caller's (a run's battery, then its service)
            engine_steps=[picture, *script, operator, *([flying] if flying else []),
                          *engine_steps],  # fmt: skip
            picture=picture,
            mission=flying,
            label={"scenario": scenario.name, "seed": seed, "dynamics": spec.dynamics},
        )
        return episode.run()
    finally:
        for o in [*engine_steps, *observers]:
            o.close()
        if command is not None:
            command.close()
        if world is not None:
            world.close()


def start_episode(
    scenario: Scenario,
    world: Dynamics,
    planner: Planner | Seat,
    command: CommandPath,
    goal: Sequence[float],
    *,
    max_steps: int,
    observers: Sequence[Observer] = (),
    picture: TrafficPicture = TRUTH,
    mission: Mission | None = None,
    label: dict | None = None,
    engine_steps: Sequence[EngineStep] = (),
) -> Episode:
    """An episode of ``world`` as every episode starts: the autopilot given the goal's
    height, judged by the scenario's rules (:meth:`Judge.from_scenario`; a ``mission`` ends
    by its own phases, not at the goal) on the scenario's clock; ``planner`` in its seat
    (:func:`uavxai.sim.seat.seat_of`)."""
    command.altitude(float(goal[2]), 0.0)  # the planner's model climbs to the goal's height
    return Episode(
        world,
        seat_of(planner),
        command,
        Judge.from_scenario(scenario, None if mission else goal),
        Clock.from_scenario(scenario),
        goal=goal,
        max_steps=max_steps,
        observers=observers,
        picture=picture,
        mission=mission,
        label=label,
        engine_steps=engine_steps,
    )


# ----------------------------------------------------------------------- kinematic runner
@dataclass
class KinematicResult:
    """One kinematic episode, as the library and the tests look at it."""

    planner: str
    seed: int
    n_intruders: int
    outcome: str
    steps: int
    min_separation_m: float
    flight_time_s: float
    final_distance_m: float
    decision_ms: list[float]
    separation_error_m: list[float]  # per decision: |branch's prediction - flown| (Trust)
    path: np.ndarray  # (steps + 1, 3) ownship at every decision and at the end
    decisions: list = field(default_factory=list)  # with keep_decisions
    records: list[dict] = field(default_factory=list)  # decisions.jsonl lines, likewise


class _Keep(Observer):
    def __init__(self, keep: bool) -> None:
        self.keep = keep
        self.path: list[np.ndarray] = []
        self.decisions: list = []
        self.records: list[dict] = []

    def on_decision(self, ep: Episode, event) -> None:
        self.path.append(event.truth.pos[0].copy())
        if self.keep:
            from uavxai.xai.explain import decision_record

            self.decisions.append(event.decision)
            self.records.append(
                decision_record(event.t, event.own, event.intruders, event.decision)
            )

    def on_end(self, ep: Episode, summary: dict) -> None:
        self.path.append(ep.state.pos[0].copy())


def run_kinematic(
    planner: str | Planner,
    scenario: Scenario,
    seed: int,
    n_intruders: int | None = None,
    *,
    goal: Sequence[float] | None = None,
    keep_decisions: bool = False,
) -> KinematicResult:
    """Fly one seeded kinematic episode of ``scenario`` with ``planner`` (a registered name
    or a planner object). ``n_intruders`` draws that many intruders (None: the scenario's);
    ``goal`` None: :func:`uavxai.sim.spec.episode_goal` of the scenario at ``seed``. The same
    seed gives the same episode (:func:`uavxai.sim.spec.episode_spec`)."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.observers import Trust

    spec = episode_spec(scenario.with_seed(seed), n_intruders=n_intruders, goal=goal)
    if isinstance(planner, str):
        config = PlannerConfig.from_scenario(spec.scenario)
        planner = make_planner(planner, config, checkpoint=spec.scenario.avoidance.checkpoint)
    trust, keep = Trust(), _Keep(keep_decisions)
    r = fly(spec, planner, observers=[trust, keep])
    return KinematicResult(
        planner=planner.name,
        seed=seed,
        n_intruders=len(spec.intruders),
        outcome=r.outcome.value,
        steps=r.steps,
        min_separation_m=r.min_separation_m,
        flight_time_s=r.flight_time_s,
        final_distance_m=float(np.linalg.norm(keep.path[-1] - np.asarray(spec.goal))),
        decision_ms=r.decision_ms,
        separation_error_m=trust.errors,
        path=np.array(keep.path),
        decisions=keep.decisions,
        records=keep.records,
    )
