"""Signals against the command line, with real processes (issue 30): a killed campaign leaves
no process behind, repeated SIGTERMs never cut an output short, and no traceback is shown.

The command-line tests start `uavxai evaluate` or `uavxai run` in a session of its own
(``start_new_session``): every process it starts (multiprocessing's forkserver and resource
tracker, the pool's workers, the companion planner, the recorder) shares that session, which is
how the tests find them. Waits poll for progress with generous deadlines. The last tests send
signals to this process itself, to check :mod:`uavxai.processes` alone.
"""

from __future__ import annotations

import csv
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import psutil
import pytest

# Tiny kinematic episodes (30 decisions each): a campaign is mostly start-up.
TINY = (
    "name: tiny\nownship: {goal: [1800, 1800, 120]}\nsurveillance: {model: truth}\n"
    "avoidance: {max_steps: 30}\n"
)
ENV = {**os.environ, "JSBSIM_DEBUG": "0", "PYTHONWARNINGS": "ignore"}
PLOTS = ("goal_rate.png", "collision_rate.png", "steps.png")


def _session(sid: int) -> list[psutil.Process]:
    """The live processes of session ``sid`` (a zombie has ended: it is only not reaped)."""
    alive = []
    for p in psutil.process_iter(["status"]):
        try:
            if os.getsid(p.pid) == sid and p.info["status"] != psutil.STATUS_ZOMBIE:
                alive.append(p)
        except (ProcessLookupError, PermissionError, psutil.Error):
            continue
    return alive


def _evaluate(tmp_path: Path, episodes: int, out: Path) -> subprocess.Popen:
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(TINY)
    return subprocess.Popen(
        [sys.executable, "-m", "uavxai", "evaluate", str(scenario), "--methods", "none",
         "--intruders", "2", "--episodes", str(episodes), "--workers", "2", "--out", str(out)],
        env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip


def _wait_for(condition, proc: subprocess.Popen, what: str, deadline_s: float = 240.0) -> None:
    end = time.monotonic() + deadline_s
    while not condition():
        if proc.poll() is not None:
            pytest.fail(f"uavxai ended before {what}: {proc.communicate()}")
        if time.monotonic() > end:
            proc.kill()
            pytest.fail(f"no {what} after {deadline_s:.0f} s")
        time.sleep(0.05)


def _workers_flying(proc: subprocess.Popen) -> bool:
    """The pool is up: the campaign, the resource tracker, the forkserver and two workers,
    the workers with episodes behind them (CPU time spent beyond their start-up)."""
    procs = _session(proc.pid)
    workers = [p for p in procs if p.pid != proc.pid and p.ppid() != proc.pid]
    if len(procs) < 5 or len(workers) < 2:
        return False
    try:
        return all(sum(w.cpu_times()[:2]) > 8.0 for w in workers)
    except psutil.Error:
        return False


def _burst(proc: subprocess.Popen, sig: int = signal.SIGTERM) -> int:
    """Send ``sig`` every 10 ms until the process ends (a supervisor that insists, a user
    pressing Ctrl-C again and again); the number sent."""
    sent = 0
    while proc.poll() is None:
        proc.send_signal(sig)
        sent += 1
        time.sleep(0.01)
    return sent


def _session_ends(sid: int, deadline_s: float = 60.0) -> list[psutil.Process]:
    """What is left of session ``sid`` once its processes have had ``deadline_s`` to end
    (the forkserver and the tracker end after the campaign, on their own)."""
    end = time.monotonic() + deadline_s
    while (left := _session(sid)) and time.monotonic() < end:
        time.sleep(0.1)
    for p in left:  # leave nothing behind for the next test
        p.kill()
    return left


def _whole_csv(path: Path) -> list[dict]:
    """The rows of a CSV that was written whole: a header and rows of as many cells."""
    text = path.read_text()
    assert text.endswith("\n"), f"{path.name} is cut short"
    rows = list(csv.reader(text.splitlines()))
    assert len(rows) >= 2 and all(len(r) == len(rows[0]) for r in rows), path.name
    return [dict(zip(rows[0], r, strict=True)) for r in rows[1:]]


def test_sigkill_of_a_campaign_leaves_no_process(tmp_path: Path) -> None:
    """SIGKILL cannot be handled: the forkserver and the workers die with their parents
    (PR_SET_PDEATHSIG) and the resource tracker then ends by itself, within 5 s."""
    proc = _evaluate(tmp_path, 400, tmp_path / "ev")
    _wait_for(lambda: len(_session(proc.pid)) >= 5, proc, "worker pool")
    started = {p.pid for p in _session(proc.pid)}
    proc.kill()
    proc.wait(timeout=60)
    left = _session_ends(proc.pid, 5.0)
    assert not left, f"processes left 5 s after SIGKILL: {[p.pid for p in left]}"
    assert len(started) >= 5  # the forkserver, the tracker and the workers were there


def test_sigkill_of_a_run_leaves_no_process(tmp_path: Path) -> None:
    """`uavxai run` flies with a companion planner and a recorder in processes of their
    own: both die with it."""
    from uavxai.paths import scenarios_dir

    out = tmp_path / "run"
    proc = subprocess.Popen(
        [sys.executable, "-m", "uavxai", "run", str(scenarios_dir() / "head_on.yaml"),
         "--out", str(out), "--realtime", "4"],
        env=ENV, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL, start_new_session=True,
    )  # fmt: skip
    decisions = out / "decisions.jsonl"
    _wait_for(lambda: decisions.exists() and decisions.stat().st_size > 0, proc, "decision")
    children = [p for p in _session(proc.pid) if p.pid != proc.pid]
    assert len(children) >= 2  # the companion and the recorder (and the resource tracker)
    proc.kill()
    proc.wait(timeout=60)
    left = _session_ends(proc.pid, 5.0)
    assert not left, f"processes left 5 s after SIGKILL: {[p.pid for p in left]}"


def test_sigterms_during_the_save_of_an_interrupted_campaign_leave_whole_files(
    tmp_path: Path,
) -> None:
    """The first SIGTERM interrupts the campaign; the ones that follow every 10 ms land in
    stopping the pool and keeping the finished episodes, and must not cut them short."""
    out = tmp_path / "ev"
    proc = _evaluate(tmp_path, 4000, out)
    _wait_for(lambda: _workers_flying(proc), proc, "episodes flown")
    sent = _burst(proc)
    _, err = proc.communicate(timeout=120)
    assert sent >= 2, "the burst never reached uavxai during its save"
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "kept the" in err, err
    episodes = _whole_csv(out / "episodes.csv")
    results = _whole_csv(out / "results.csv")
    assert 1 <= len(episodes) < 4000
    assert int(results[0]["episodes"]) == len(episodes)
    assert not list(out.glob(".*.part"))  # no temporary file left
    assert not _session_ends(proc.pid)


def test_sigterms_during_the_final_save_wait_for_it(tmp_path: Path) -> None:
    """A campaign that has flown every episode is saving: episodes.csv first, then
    results.csv and the plots. SIGTERMs sent from the moment episodes.csv appears wait for
    the save to end; the campaign then exits 130 (interrupted) with every file whole, or 0
    if it was done before the first one came."""
    out = tmp_path / "ev"
    proc = _evaluate(tmp_path, 6, out)
    _wait_for(lambda: (out / "episodes.csv").exists(), proc, "final save")
    _burst(proc)
    _, err = proc.communicate(timeout=120)
    assert proc.returncode in (0, 130), err
    assert "Traceback" not in err, err
    assert len(_whole_csv(out / "episodes.csv")) == 6
    assert int(_whole_csv(out / "results.csv")[0]["episodes"]) == 6
    for name in PLOTS:
        assert (out / name).read_bytes().startswith(b"\x89PNG"), name
    assert not list(out.glob(".*.part"))
    assert not _session_ends(proc.pid)


@pytest.fixture
def own_signal_handlers():
    """The test changes this process's SIGINT and SIGTERM handlers; they are put back."""
    previous = {sig: signal.getsignal(sig) for sig in (signal.SIGINT, signal.SIGTERM)}
    yield
    for sig, handler in previous.items():
        signal.signal(sig, handler)


def test_a_signal_during_a_deferred_save_comes_after_it(own_signal_handlers) -> None:
    from uavxai.processes import interrupts_deferred, raise_on_interrupt

    raise_on_interrupt(once=False)
    saved = []
    with pytest.raises(KeyboardInterrupt), interrupts_deferred() as caught:
        signal.raise_signal(signal.SIGTERM)
        saved.append("the rest of the save")
    assert saved == ["the rest of the save"] and caught == [signal.SIGTERM]
    with interrupts_deferred(deliver=False) as caught:  # already ending: dropped
        signal.raise_signal(signal.SIGINT)
    assert caught == [signal.SIGINT]
    with pytest.raises(KeyboardInterrupt):  # the handlers are back
        signal.raise_signal(signal.SIGINT)


def test_the_program_is_interrupted_once(own_signal_handlers) -> None:
    from uavxai.processes import raise_on_interrupt

    raise_on_interrupt(once=True)
    with pytest.raises(KeyboardInterrupt):
        signal.raise_signal(signal.SIGTERM)
    signal.raise_signal(signal.SIGTERM)  # ignored: the program is ending already
    signal.raise_signal(signal.SIGINT)


def test_the_command_line_called_from_python_gives_the_callers_handlers_back(tmp_path) -> None:
    """A test runner (or any caller) keeps its own SIGINT/SIGTERM handling once `main`
    returns (issue 30: pytest ignored SIGTERM after the CLI had run in-process)."""
    from uavxai.cli import main

    def mine(signum, frame) -> None:
        pass

    before = {s: signal.signal(s, mine) for s in (signal.SIGINT, signal.SIGTERM)}
    try:
        scenario = Path(__file__).resolve().parents[1] / "scenarios" / "head_on.yaml"
        assert main(["validate", str(scenario)]) == 0
        assert signal.getsignal(signal.SIGINT) is mine
        assert signal.getsignal(signal.SIGTERM) is mine
    finally:
        for s, h in before.items():
            signal.signal(s, h)


def test_a_campaign_flown_in_process_leaves_nothing_that_turns_a_child_deaf() -> None:
    """A worker pool started in this process (as a test runner or a user's script does) must
    not leave its forkserver's marker in the environment: a `uavxai` started afterwards
    inherited it, took itself for a forkserver and ignored SIGTERM (issue 30)."""
    from uavxai import forkserver_preload
    from uavxai.campaign import run_campaign
    from uavxai.scenario import default_scenario

    run_campaign(default_scenario(), ["none"], [2], 2, workers=2)
    assert forkserver_preload.STARTED_BY not in os.environ
    child = subprocess.run(
        [sys.executable, "-c", "import signal, uavxai.forkserver_preload; "
         "print(signal.getsignal(signal.SIGTERM) == signal.SIG_DFL)"],
        env=ENV, capture_output=True, text=True, timeout=120,
    )  # fmt: skip
    assert child.stdout.strip() == "True", child.stderr


def test_a_pooled_campaign_takes_a_signal_between_waits_not_inside_them() -> None:
    """A signal during a pooled campaign is noted, then raised once the current wait is over:
    a KeyboardInterrupt raised inside concurrent.futures' `wait` (it takes every future's lock
    in turn) could leave a lock held, and the pool's thread then waited for it at exit for
    ever (seen once in CI: a campaign under a burst of SIGTERMs saved and never ended)."""
    import threading

    from uavxai.campaign import run_campaign
    from uavxai.scenario import default_scenario

    mine = signal.getsignal(signal.SIGINT)
    seen: list = []

    def on_done(row: dict) -> None:
        seen.append(signal.getsignal(signal.SIGINT))
        if len(seen) == 3:
            signal.raise_signal(signal.SIGINT)  # as a Ctrl-C would, mid-campaign

    with pytest.raises(KeyboardInterrupt):
        run_campaign(default_scenario(), ["none"], [2], 400, workers=2, on_done=on_done)
    assert 3 <= len(seen) < 400
    assert all(h not in (mine, signal.SIG_DFL, signal.default_int_handler) for h in seen)
    assert signal.getsignal(signal.SIGINT) is mine  # the caller's handler back
    deadline = time.monotonic() + 10.0
    while time.monotonic() < deadline and any(
        "ExecutorManagerThread" in type(t).__name__ for t in threading.enumerate()
    ):
        time.sleep(0.1)
    assert not [t for t in threading.enumerate() if "ExecutorManagerThread" in type(t).__name__]
