"""The avoidance planner on a companion computer: its own process, its own core.

On a real UAV the detect-and-avoid planner runs on a companion computer beside the
autopilot; its command reaches the autopilot a processing latency after the picture it was
planned from. The co-simulation models exactly that with ``avoidance.decision_latency_s``:
the episode engine takes the picture at t, and applies the command at t + latency
(:class:`uavxai.sim.episode.Episode`). Because the command is not needed before then, the
planner can think while the world flies on, and :class:`Companion` runs it in a separate
process so that JSBSim (which holds the GIL while it integrates) and the search use both
cores.

What is flown does not depend on where the planner runs: the picture is fixed at t, the
planner is seeded and fed the same requests in the same order, and the engine waits for the
answer at t + latency however long the search took. ``uavxai run`` uses a companion when the
latency is above 0; ``uavxai evaluate`` plans in-process (its episodes already fill the
cores), and both fly the same episode (tests/test_sim_latency.py).
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import traceback
from collections.abc import Sequence
from multiprocessing.connection import Connection
from pathlib import Path

from uavxai.avoidance.types import Decision, Goal, Intruder, Ownship, PlannerConfig
from uavxai.errors import UserError


def _serve(conn: Connection, name: str, config: PlannerConfig, checkpoint: str | None) -> None:
    """The companion's loop: build the planner, then answer requests until told to stop.
    Every answer is ("ok", value) or ("error", text) so that a failure in the planner
    reaches the simulation as a message, not as a silent hang."""
    try:
        from uavxai.avoidance.planners import make_planner

        planner = make_planner(name, config, checkpoint=checkpoint)
        conn.send(("ok", None))
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises it
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    while True:
        try:
            method, args, kwargs = conn.recv()
        except (EOFError, KeyboardInterrupt):
            return
        if method == "close":
            return
        try:
            conn.send(("ok", getattr(planner, method)(*args, **kwargs)))
        except Exception:  # noqa: BLE001 - as above
            conn.send(("error", traceback.format_exc(limit=4)))


class Companion:
    """A planner (``make_planner(name, config, checkpoint)``) running in its own process,
    behind the :class:`~uavxai.avoidance.types.Planner` interface plus :meth:`submit` /
    :meth:`result`, which let the caller fly on while it plans.

    The process is started with ``spawn`` (no fork of a process that holds JSBSim, rerun
    and torch threads); it costs about a second once, while the world loads its aircraft,
    and is waited for at the first call (``reset``, before the episode's clock starts).
    """

    def __init__(
        self, name: str, config: PlannerConfig, checkpoint: str | Path | None = None
    ) -> None:
        self.name = name
        self.config = config
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve,
            args=(child, name, config, None if checkpoint is None else str(checkpoint)),
            name=f"uavxai-companion-{name}",
            daemon=True,
        )
        self._proc.start()
        child.close()
        self._waiting = False
        self._started = False  # confirmed at the first call: start-up overlaps the world's

    def _start(self) -> None:
        if not self._started:
            self._receive("start the planner")
            self._started = True

    # ------------------------------------------------------------------ Planner interface
    def reset(self, seed: int) -> None:
        self._call("reset", seed)

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
        if self._waiting:
            raise RuntimeError("the companion is still planning; call result() first")
        self._start()
        self._conn.send(("plan", (own, list(intruders), tuple(goal)), {"step": step}))
        self._waiting = True

    def result(self) -> Decision:
        """The decision of the last :meth:`submit`, waiting for it if the search is not done."""
        if not self._waiting:
            raise RuntimeError("nothing submitted to the companion")
        self._waiting = False
        return self._receive("plan")

    def close(self) -> None:
        if self._proc.is_alive():
            with contextlib.suppress(BrokenPipeError, OSError):
                self._conn.send(("close", (), {}))
            self._proc.join(timeout=5)
            if self._proc.is_alive():
                self._proc.kill()
        self._conn.close()

    def __enter__(self) -> Companion:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()

    # ------------------------------------------------------------------------ internals
    def _call(self, method: str, *args: object) -> object:
        if self._waiting:
            self.result()  # an abandoned plan: drain it so the answers stay in order
        self._start()
        self._conn.send((method, args, {}))
        return self._receive(method)

    def _receive(self, what: str):
        try:
            status, value = self._conn.recv()
        except EOFError:
            code = self._proc.exitcode
            raise RuntimeError(
                f"the companion planner process ({self.name}) ended (exit code {code}) "
                f"while asked to {what}. It is started with multiprocessing's 'spawn', which "
                "imports the main script again: a script that flies a run with "
                "avoidance.decision_latency_s > 0 must keep its top level under "
                '`if __name__ == "__main__":`'
            ) from None
        if status == "error":
            if what == "start the planner":
                self._proc.join(timeout=5)
                raise UserError(f"avoidance planner '{self.name}' could not start: {value}")
            raise RuntimeError(f"the companion planner ({self.name}) failed to {what}:\n{value}")
        return value
