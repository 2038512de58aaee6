"""SIGTERM and SIGINT end a run cleanly: whole files, a summary marked `interrupted`."""

from __future__ import annotations

import contextlib
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest

from uavxai.paths import scenarios_dir


@pytest.mark.parametrize(
    ("sig", "latency", "group"),
    [
        (signal.SIGTERM, 0.0, False),
        (signal.SIGINT, 0.0, False),
        (signal.SIGINT, 0.5, True),
        (signal.SIGTERM, 0.0, True),
    ],
    ids=[
        "sigterm",
        "sigint",
        "ctrl-c-to-the-group-with-a-companion",
        "sigterms-to-the-group-again-and-again",
    ],
)
def test_a_signal_leaves_whole_files_and_an_interrupted_summary(
    tmp_path: Path, sig, latency: float, group: bool
) -> None:
    """Sent to the group, the signal reaches every process as from a terminal (Ctrl-C) or a
    supervisor (SIGTERM to a process group): the companion planner and the recorder process
    too, which leave it to the run to close them. The SIGTERMs to the group go on every
    10 ms until the run has ended: the ones that come while it saves change nothing."""
    import yaml

    out = tmp_path / "run"
    scenario = yaml.safe_load((scenarios_dir() / "head_on.yaml").read_text())
    scenario.setdefault("avoidance", {})["decision_latency_s"] = latency
    path = tmp_path / "head_on.yaml"
    path.write_text(yaml.safe_dump(scenario))
    env = {**os.environ, "JSBSIM_DEBUG": "0"}
    proc = subprocess.Popen(
        [sys.executable, "-m", "uavxai", "run", str(path), "--out", str(out), "--realtime", "4"],
        env=env, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
        start_new_session=True,
    )  # fmt: skip
    deadline = time.monotonic() + 120
    while not (out / "decisions.jsonl").exists() or (out / "decisions.jsonl").stat().st_size == 0:
        assert proc.poll() is None and time.monotonic() < deadline, proc.communicate()
        time.sleep(0.2)
    time.sleep(2.0)
    if not group:
        proc.send_signal(sig)
    elif sig == signal.SIGINT:
        os.killpg(proc.pid, sig)
    else:
        while proc.poll() is None:
            with contextlib.suppress(ProcessLookupError):  # the group may be gone already
                os.killpg(proc.pid, sig)
            time.sleep(0.01)
    _, err = proc.communicate(timeout=60)
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "interrupted" in err and "internal error" not in err
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "interrupted" and summary["steps"] >= 1
    rows = (out / "trajectory.csv").read_text().splitlines()
    assert all(len(r.split(",")) == 12 for r in rows)  # no row cut mid-write
    from rerun.chunk import RrdReader

    chunks = RrdReader(out / "run.rrd").stream().to_chunks()
    assert any(c.entity_path == "/xai/tree" for c in chunks)


def test_sigterm_on_evaluate_keeps_finished_episodes_and_stops_the_workers(tmp_path: Path):
    scenario = tmp_path / "quick.yaml"
    scenario.write_text(
        "name: quick\nownship: {goal: [1800, 1800, 120]}\nsurveillance: {model: truth}\n"
    )
    out = tmp_path / "ev"
    proc = subprocess.Popen(
        [sys.executable, "-m", "uavxai", "evaluate", str(scenario), "--methods", "none",
         "--intruders", "5", "--episodes", "400", "--workers", "2", "--out", str(out)],
        env={**os.environ, "JSBSIM_DEBUG": "0"}, stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE, text=True,
    )  # fmt: skip
    # stderr read as it comes (a full pipe would stall the campaign); its end is the end of
    # every process that holds it: uavxai and anything it started
    said: list[str] = []
    reader = threading.Thread(target=lambda: said.append(proc.stderr.read()), daemon=True)
    reader.start()
    # mid-campaign: once episodes have finished (journaled), however loaded the machine is
    journal = out / "episodes.journal.jsonl"
    deadline = time.monotonic() + 300.0
    while time.monotonic() < deadline and proc.poll() is None and (
        not journal.exists() or journal.read_text().count("\n") < 3
    ):
        time.sleep(0.2)
    children = subprocess.run(
        ["pgrep", "-P", str(proc.pid)], capture_output=True, text=True
    ).stdout.split()
    proc.send_signal(signal.SIGTERM)
    try:
        proc.wait(timeout=60)
    finally:
        if proc.poll() is None:  # say what is left before failing
            tree = subprocess.run(["ps", "-o", "pid,ppid,stat,args", "--ppid", str(proc.pid)],
                                  capture_output=True, text=True).stdout  # fmt: skip
            state = _signal_state(proc.pid)
            proc.kill()
            pytest.fail(f"uavxai still running 60 s after SIGTERM; its children:\n{tree}"
                        f"its state:\n{state}")  # fmt: skip
    reader.join(timeout=30)
    assert not reader.is_alive(), "a process uavxai started still holds its stderr"
    err = said[0]
    assert proc.returncode == 130, err
    assert "Traceback" not in err and "kept the" in err
    rows = (out / "episodes.csv").read_text().splitlines()
    assert 1 < len(rows) < 401  # the finished ones, not all
    time.sleep(1.0)
    alive = [c for c in children if Path(f"/proc/{c}").exists()
             and "zombie" not in Path(f"/proc/{c}/status").read_text().lower()]  # fmt: skip
    assert not alive, f"worker processes still running: {alive}"


def _signal_state(pid: int) -> str:
    """What a stuck process is doing: its signal masks and each thread's kernel wait."""
    lines = []
    with contextlib.suppress(OSError):
        status = Path(f"/proc/{pid}/status").read_text().splitlines()
        lines += [x for x in status if x.startswith(("State", "Sig", "Shd", "Threads"))]
        for task in sorted(Path(f"/proc/{pid}/task").iterdir()):
            with contextlib.suppress(OSError):
                name = (task / "comm").read_text().strip()
                wchan = (task / "wchan").read_text().strip()
                blk = next(x for x in (task / "status").read_text().splitlines()
                           if x.startswith("SigBlk"))  # fmt: skip
                lines.append(f"thread {task.name} {name}: {wchan} {blk}")
    return "\n".join(lines)
