"""Progress where no terminal shows a bar (a log file, CI, a batch job): lines now and then,
one when a task completes, and a whole campaign's progress in its log."""

from __future__ import annotations

import io
from pathlib import Path

import pytest
from rich.console import Console
from rich.progress import Progress

from uavxai.campaign import evaluate_command
from uavxai.progress import LineProgress, progress_bar
from uavxai.scenario import default_scenario


class Clock:
    def __init__(self) -> None:
        self.t = 0.0

    def __call__(self) -> float:
        return self.t


def _console(terminal: bool) -> tuple[Console, io.StringIO]:
    buf = io.StringIO()
    return Console(file=buf, force_terminal=terminal, width=200), buf


def test_a_terminal_gets_the_bar_and_a_log_gets_lines() -> None:
    assert isinstance(progress_bar(_console(True)[0]), Progress)
    assert isinstance(progress_bar(_console(False)[0]), LineProgress)


def test_lines_at_most_every_interval_and_one_at_the_end() -> None:
    console, buf = _console(False)
    clock = Clock()
    with LineProgress(console, every_s=60.0, clock=clock) as progress:
        task = progress.add_task("campaign", total=10)
        for _ in range(9):
            clock.t += 20.0
            progress.update(task, advance=1, description="campaign")
        assert len(buf.getvalue().splitlines()) == 3  # at 60, 120 and 180 s
        clock.t += 20.0
        progress.update(task, advance=1)
    lines = buf.getvalue().splitlines()
    assert len(lines) == 4  # the completion, and nothing more on leaving
    assert "campaign: 3/10 (30 %), 1m00s elapsed, about 2m20s left" in lines[0]
    assert "campaign: 10/10 (100 %), 3m20s elapsed" in lines[-1] and "left" not in lines[-1]


def test_a_task_that_stops_short_says_where_on_leaving() -> None:
    console, buf = _console(False)
    with pytest.raises(KeyboardInterrupt), LineProgress(console, clock=Clock()) as progress:
        task = progress.add_task("run", total=400, status="")
        progress.update(task, advance=7, status="t=7s")
        raise KeyboardInterrupt
    last = buf.getvalue().splitlines()[-1]
    assert last.endswith("run: 7/400 (2 %), 0s elapsed, about 0s left; t=7s")


def test_a_campaign_logs_its_progress(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    evaluate_command(
        default_scenario("progress-test"),
        methods=["none"],
        intruders=[3],
        episodes=3,
        dynamics="kinematic",
        workers=1,
        ray_address=None,
        out=tmp_path,
    )
    err = capsys.readouterr().err
    assert "none x3: goal: 3/3 (100 %)" in err


def test_a_missions_bar_counts_what_it_will_fly_and_ends_full() -> None:
    """The bar's total is the decisions the mission will take (transit, time on station,
    return), refined as it flies, not the step budget (2 max_steps + service_s), and at the
    end it is the decisions flown: the bar ends at 100 % (issue 30)."""
    import dataclasses

    from rich.console import Console
    from rich.progress import Progress

    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.build import fly
    from uavxai.sim.episode import Observer
    from uavxai.sim.mission import mission_of
    from uavxai.sim.observers import ProgressBar
    from uavxai.sim.spec import episode_spec

    class Totals(Observer):
        def __init__(self) -> None:
            self.rows: list[tuple[float, float | None]] = []

        def on_period(self, ep, event, flown_min_m) -> None:
            task = progress.tasks[bar.task]
            self.rows.append((task.completed, task.total))

    station = (1000.0, 1000.0, 120.0)
    sc = default_scenario("mission-progress", intruders={"count": 0}, seed=1)
    mission = dataclasses.replace(mission_of(sc, station), service_s=60.0)
    totals = Totals()
    with Progress(console=Console(file=io.StringIO())) as progress:
        bar = ProgressBar(progress, sc.name, sc.avoidance.max_steps)
        planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
        r = fly(
            episode_spec(sc, goal=station, dynamics="kinematic", mission=mission),
            planner,
            observers=[bar, totals],
        )
        end = progress.tasks[bar.task]
    assert r.summary["mission"]["phases"].keys() == {"transit", "on_station", "returning"}
    assert end.completed == end.total == r.steps
    budget = 2 * sc.avoidance.max_steps + 60
    assert r.steps < budget / 4  # the old total would have left the bar at a quarter
    # once the first legs' speed is known, every estimate is within 10 % of what was flown
    for done, total in totals.rows[20:]:
        assert total is not None and abs(total - r.steps) <= 0.1 * r.steps, (done, total)
