"""The avoidance planner on a companion computer: its own process, its own core.

On a real UAV the detect-and-avoid planner runs on a companion computer beside the
autopilot; its command reaches the autopilot a processing latency after the picture it was
planned from. The co-simulation models exactly that with ``avoidance.decision_latency_s``:
the episode engine takes the picture at t, and applies the command at t + latency
(:class:`uavxai.sim.episode.Episode`). Because the command is not needed before then, the
planner can think while the world flies on, and :class:`Companion` runs it in a separate
process so that JSBSim (which holds the GIL while it integrates) and the search use both
cores. Without a latency (the paper's instant decision) the ownship must wait for the
command, but the intruders need not: the world flies them through the period ahead while
the companion searches (:meth:`uavxai.dynamics.world.JSBSimWorld.lookahead`, the same
flight to the bit). The ADS-B receiver and the tracker run there too (:class:`Onboard`), as
on the UAV: the simulation sends the ADSB_VEHICLE frames (a decision period's with the next
request, :class:`_RemoteReceiver`) and the companion decodes and tracks them on its own core,
in the order they arrived; the beliefs come back at each decision.

What is flown does not depend on where the planner runs: the picture is fixed at t, the
planner and the tracker are seeded and fed the same requests in the same order, and the
engine waits for the answer at t + latency however long the search took. ``uavxai run``
always plans on a companion; ``uavxai evaluate`` plans in-process (its episodes already fill
the cores), and both fly the same episode (tests/test_sim_latency.py,
tests/test_sim_engine.py).
"""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

from uavxai.avoidance.types import Decision, Goal, Intruder, Ownship, PlannerConfig
from uavxai.scenario import Scenario
from uavxai.sim.picture import Receiver
from uavxai.sim.seat import Seat
from uavxai.worker import Worker


def warm_up(name: str, config: PlannerConfig, checkpoint: str | None) -> None:
    """One decision of a planner of its own, on a made-up encounter, thrown away.

    Why: a process's first MCTS search loads the compiled kernel from numba's cache: 0.3-0.6 s,
    against 3-15 ms for every later decision (issue 31, measured in ``uavxai run``'s companion,
    where that first decision held the ownship up for half a second of a one-minute flight).
    Done when the companion starts, it overlaps the world's loading of its aircraft. A
    planner of its own, so the episode's planner keeps no trace of it (its generator, its
    memo): the flight is the same to the bit. Only the registered planners that search with
    the compiled kernel (:func:`uavxai.avoidance.planners.uses_compiled_search`; the others'
    first decision costs what every later one does, and a plugin's is not asked to plan
    what nobody flies).
    A planner that fails here would fail in flight: the error says it came from here."""
    from uavxai.avoidance.planners import PLANNERS, make_planner, uses_compiled_search

    if name not in PLANNERS:
        return
    planner = make_planner(name, config, checkpoint=checkpoint)
    if not uses_compiled_search(planner):
        return
    planner.reset(config.seed)
    (x0, x1), (y0, y1), (h0, h1) = config.x_bounds, config.y_bounds, config.h_bounds
    x, y, h = (x0 + x1) / 2, (y0 + y1) / 2, (h0 + h1) / 2
    v = sum(config.speed_mps) / 2
    own = Ownship(x, y, h, speed=v, heading=0.0, ground_velocity=(0.0, v))
    traffic = [  # head-on, and crossing from the right a little above: the search works
        Intruder(1, x, y + 15 * v, h, 0.0, -v, sigma_m=5.0, sigma_v=1.0),
        Intruder(2, x + 12 * v, y + 12 * v, h + 10, -v, 0.0, turn_rate=0.02,
                 sigma_h_m=2.0, sigma_vh=0.3, bank_limit_deg=20.0),  # fmt: skip
    ]
    try:
        planner.plan(own, traffic, (x, y + 0.4 * (y1 - y0), h))
    except Exception as exc:
        raise RuntimeError(
            f"planner {name!r} failed on the warm-up's made-up encounter (a head-on and a "
            f"crossing, uavxai.sim.companion.warm_up): {type(exc).__name__}: {exc}"
        ) from exc


class Onboard:
    """What runs on the companion computer: the avoidance planner and, given the scenario,
    the surveillance :class:`~uavxai.sim.picture.Receiver` (ADS-B decoding and tracking).
    Its planner is warmed up as it is built (:func:`warm_up`)."""

    def __init__(
        self, name: str, config: PlannerConfig, checkpoint: str | None, scenario: Scenario | None
    ) -> None:
        from uavxai.avoidance.planners import make_planner

        self.planner = make_planner(name, config, checkpoint=checkpoint)
        self.receiver = Receiver(scenario) if scenario is not None else None
        warm_up(name, config, checkpoint)

    def reset(self, seed: int) -> None:
        self.planner.reset(seed)

    def plan(self, *args, **kwargs) -> Decision:
        return self.planner.plan(*args, **kwargs)

    def receive(self, *args) -> None:
        self.receiver.receive(*args)

    def plan_onboard(
        self, own: Ownship, t: float, goal: Goal, *, step: int = 0
    ) -> tuple[list[Intruder], Decision]:
        """Plan from this receiver's beliefs at ``t``; both come back."""
        intruders = self.receiver.beliefs(t)
        return intruders, self.planner.plan(own, intruders, goal, step=step)

    def beliefs(self, t: float) -> list[Intruder]:
        return self.receiver.beliefs(t)


class _RemoteReceiver:
    """The companion's receiver seen from the simulation: frames go out with the next request
    (a decision, a picture), a decision period's in one pipe write (at most the worker's batch,
    64 posts, a write: more samples a period than that go in several), and are decoded and
    tracked there before it, in the order they came; beliefs come back when asked.

    Why not each sample's at once: every write wakes the companion, and on a busy machine the
    woken process took the simulation's core from it (issue 31: 0.25 s of a one-minute run
    waiting in 600 writes of 0.3 ms of work each). The companion decodes a period's frames
    (~3 ms) while the world flies the intruders ahead, beside the search."""

    def __init__(self, worker: Worker) -> None:
        self._worker = worker

    def receive(self, frames: bytes, onboard: Sequence, t: float) -> None:
        self._worker.post("receive", frames, list(onboard), t)

    def beliefs(self, t: float) -> list[Intruder]:
        return self._worker.call("beliefs", t)


class Companion(Seat):
    """A planner (``make_planner(name, config, checkpoint)``) on its own process, behind the
    :class:`~uavxai.avoidance.types.Planner` interface and in the engine's
    :class:`~uavxai.sim.seat.Seat` (:meth:`submit` / :meth:`result`, which let the caller fly
    on while it plans). Given the ``scenario``, the process also decodes and tracks the
    traffic: :attr:`receiver` is the episode's picture's receiver.

    Starting the process costs about a second once (the planner warmed up: :func:`warm_up`),
    while the world loads its aircraft, and is waited for at the first call (``reset``,
    before the episode's clock starts).
    """

    def __init__(
        self,
        name: str,
        config: PlannerConfig,
        checkpoint: str | Path | None = None,
        scenario: Scenario | None = None,
    ) -> None:
        self.name = name
        self.config = config
        self.parallel = True  # its own process: the world flies on while it searches
        path = None if checkpoint is None else str(checkpoint)
        self._worker = Worker(Onboard, name, config, path, scenario, name=f"planner '{name}'")
        self.receiver = _RemoteReceiver(self._worker) if scenario is not None else None
        self.beliefs: list[Intruder] = []  # the picture of the last submit_onboard
        self._onboard = False

    @property
    def pid(self) -> int | None:
        return self._worker.pid

    # ------------------------------------------------------------------ Planner interface
    def reset(self, seed: int) -> None:
        self._worker.call("reset", seed)

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        self.submit(own, intruders, goal, step=step)
        return self.result()

    # ------------------------------------------------------------------ planning in flight
    def submit(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> None:
        """Start planning; :meth:`result` returns the decision."""
        self._worker.submit("plan", own, list(intruders), tuple(goal), step=step)

    def submit_onboard(self, own: Ownship, t: float, goal: Goal, *, step: int = 0) -> None:
        """Start planning from the companion's own picture of the traffic at ``t`` (its
        :attr:`receiver`'s beliefs, as :meth:`submit` would be given them, without the round
        trip); :meth:`result` returns the decision and :attr:`beliefs` the picture."""
        self._worker.submit("plan_onboard", own, t, tuple(goal), step=step)
        self._onboard = True

    def result(self) -> Decision:
        """The decision of the last :meth:`submit`, waiting for it if the search is not done."""
        value = self._worker.result()
        if self._onboard:
            self._onboard = False
            self.beliefs, value = value
        return value

    def close(self) -> None:
        self._worker.close()

    def __enter__(self) -> Companion:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()
