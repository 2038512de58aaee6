"""The engine's seams are typed (issue 29): sim/ calls what its seats, command paths, worlds
and pictures declare, and never asks an object what it is with getattr/hasattr."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

import pytest

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.scenario import default_scenario
from uavxai.sim.build import fly
from uavxai.sim.companion import Companion
from uavxai.sim.seat import InProcess, Seat, seat_of
from uavxai.sim.spec import episode_spec

SIM = Path(__file__).resolve().parents[1] / "uavxai" / "sim"

# (file, the first argument's source) -> why getattr/hasattr is right there. Anything else is
# a seam asked what it is: declare it on the seam's Protocol/ABC instead.
ALLOWED = {
    ("flight_quality.py", "self"): "the row of its own declared COLUMNS fields, by name",
    ("command.py", "msg"): "pymavlink messages: only some types carry target_system",
}


def _introspection(path: Path) -> list[tuple[str, str, int]]:
    """Every getattr/hasattr call in ``path``: (file, first argument's source, line)."""
    found = []
    for node in ast.walk(ast.parse(path.read_text(), str(path))):
        if (
            isinstance(node, ast.Call)
            and isinstance(node.func, ast.Name)
            and node.func.id in ("getattr", "hasattr")
        ):
            first = ast.unparse(node.args[0]) if node.args else ""
            found.append((path.name, first, node.lineno))
    return found


def test_sim_asks_no_seam_what_it_is() -> None:
    calls = [c for p in sorted(SIM.glob("*.py")) for c in _introspection(p)]
    seams = [f"{f}:{n} getattr/hasattr({a}, ...)" for f, a, n in calls if (f, a) not in ALLOWED]
    assert not seams, "declare these on the seam's type instead:\n" + "\n".join(seams)
    # the allow-list holds only what is still there: a stale reason hides nothing new
    assert {(f, a) for f, a, _ in calls} == set(ALLOWED)


def test_the_scan_finds_introspection(tmp_path: Path) -> None:
    """The scan is not blind: it finds both calls, with their first arguments."""
    src = tmp_path / "seam.py"
    src.write_text('x = getattr(planner, "submit", None)\nif hasattr(command, "bridge"): ...\n')
    assert _introspection(src) == [("seam.py", "planner", 1), ("seam.py", "command", 2)]


class _Counted(Seat):
    """A seat of its own, as user code could write one: a planner that counts its calls."""

    def __init__(self, planner) -> None:
        self.inner = InProcess(planner)
        self.name, self.config = planner.name, planner.config
        self.submits = 0

    def reset(self, seed: int) -> None:
        self.inner.reset(seed)

    def submit(self, own, intruders, goal, *, step: int = 0) -> None:
        self.submits += 1
        self.inner.submit(own, intruders, goal, step=step)

    def result(self):
        return self.inner.result()


def _summary(r) -> dict:
    """What an episode flew, without what the wall clock measured."""
    return {k: v for k, v in r.summary.items() if k not in ("decision_ms", "sim_realtime_factor")}


@pytest.mark.parametrize("latency_s", [0.0, 0.5])
def test_any_seat_flies_the_episode_the_planner_flies_in_process(latency_s: float) -> None:
    """The engine uses only what Seat declares: a seat written outside sim/ flies the same
    episode as the planner itself (seated in-process), submitted to once per decision."""
    sc = default_scenario(
        "seams", seed=3, avoidance={"max_steps": 40, "decision_latency_s": latency_s}
    )
    spec = episode_spec(sc, n_intruders=2, dynamics="kinematic")
    config = dataclasses.replace(PlannerConfig.from_scenario(sc), simulations=40)
    plain = fly(spec, make_planner("mcts", config))
    seat = _Counted(make_planner("mcts", config))
    seated = fly(spec, seat)
    assert _summary(seated) == _summary(plain)
    assert seat.submits == seated.steps > 0


def test_seats_declare_what_the_engine_reads() -> None:
    planner = make_planner("none", PlannerConfig())
    seat = seat_of(planner)
    assert isinstance(seat, InProcess) and seat_of(seat) is seat
    assert (seat.name, seat.config, seat.receiver, seat.parallel) == (
        "none", planner.config, None, False
    )
    with pytest.raises(NotImplementedError, match="no receiver"):
        seat.submit_onboard(None, 0.0, (0.0, 0.0, 100.0))
    with pytest.raises(RuntimeError, match="without a submit"):
        seat.result()
    assert issubclass(Companion, Seat) and Companion.result is not Seat.result
