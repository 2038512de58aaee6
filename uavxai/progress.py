"""The progress bar of uavxai's long commands (training, campaigns, runs): one look everywhere,
and on stderr, so that stdout stays for results.

Where no terminal shows a bar (a log file, `nohup`, CI, a batch job on a cluster) rich draws
nothing until the end, so an hour-long campaign would look dead; there the same calls print a
plain line now and then instead (:class:`LineProgress`)."""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from rich.console import Console
from rich.progress import (
    BarColumn,
    MofNCompleteColumn,
    Progress,
    ProgressColumn,
    TextColumn,
    TimeElapsedColumn,
    TimeRemainingColumn,
)

LINE_EVERY_S = 60.0  # a line at most this often per task, and one when it completes


def progress_bar(
    console: Console | None = None, columns: tuple[ProgressColumn, ...] | None = None
) -> Progress | LineProgress:
    """Description, bar, done / total, elapsed and remaining time (or ``columns``) on a
    terminal; elsewhere a :class:`LineProgress` taking the same calls."""
    console = console or Console(stderr=True)
    if not console.is_terminal:
        return LineProgress(console)
    columns = columns or (
        TextColumn("[bold]{task.description}"),
        BarColumn(),
        MofNCompleteColumn(),
        TimeElapsedColumn(),
        TimeRemainingColumn(),
    )
    return Progress(*columns, console=console)


@dataclass
class _Task:
    description: str
    total: float | None
    fields: dict[str, Any]
    started: float
    said: float  # when its last line was printed
    completed: float = 0.0
    said_count: float = 0.0  # what its last line reported
    done_said: bool = False


class LineProgress:
    """The calls of a rich ``Progress`` that uavxai makes (``add_task``, ``update``, the
    ``with`` block), answered by a line at most every ``every_s`` per task and one when a task
    completes: ``12:03:04 manoeuvring (jsbsim): 40/800 (5 %), 5m10s elapsed, about 1h38m
    left``."""

    def __init__(
        self,
        console: Console,
        every_s: float = LINE_EVERY_S,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.console, self.every_s, self.clock = console, every_s, clock
        self.tasks: list[_Task] = []

    def __enter__(self) -> LineProgress:
        return self

    def __exit__(self, *exc: object) -> None:
        # where a task stopped short (interrupted, or a run that ended early): say where
        for i, t in enumerate(self.tasks):
            if not t.done_said and t.completed != t.said_count:
                self._say(i)

    def add_task(self, description: str, total: float | None = 100.0, **fields: Any) -> int:
        now = self.clock()
        self.tasks.append(_Task(description, total, fields, started=now, said=now))
        return len(self.tasks) - 1

    def update(
        self,
        task_id: int,
        *,
        total: float | None = None,
        completed: float | None = None,
        advance: float | None = None,
        description: str | None = None,
        **fields: Any,
    ) -> None:
        t = self.tasks[task_id]
        if total is not None:
            t.total = total
        if completed is not None:
            t.completed = completed
        if advance is not None:
            t.completed += advance
        if description is not None:
            t.description = description
        t.fields.update(fields)
        finished = t.total is not None and t.completed >= t.total
        if (finished and not t.done_said) or self.clock() - t.said >= self.every_s:
            self._say(task_id)
            t.done_said = finished

    def _say(self, task_id: int) -> None:
        t = self.tasks[task_id]
        now = self.clock()
        t.said, t.said_count = now, t.completed
        elapsed = now - t.started
        status = " ".join(str(v) for v in t.fields.values() if v not in ("", None))
        line = f"{time.strftime('%H:%M:%S')} {t.description}: {t.completed:g}"
        if t.total:
            line += f"/{t.total:g} ({100.0 * t.completed / t.total:.0f} %)"
        line += f", {_duration(elapsed)} elapsed"
        if t.total and 0 < t.completed < t.total:
            left = elapsed / t.completed * (t.total - t.completed)
            line += f", about {_duration(left)} left"
        if status:
            line += f"; {status}"
        self.console.print(line, highlight=False, markup=False, soft_wrap=True)


def _duration(seconds: float) -> str:
    s = int(round(seconds))
    if s < 60:
        return f"{s}s"
    if s < 3600:
        return f"{s // 60}m{s % 60:02d}s"
    return f"{s // 3600}h{s % 3600 // 60:02d}m"
