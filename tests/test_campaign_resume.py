"""A campaign killed half-way resumes from the episodes it journaled (issue 27, part 5): the
resumed campaign's files are the uninterrupted campaign's, planner times aside."""

from __future__ import annotations

import csv
import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from uavxai.campaign import TIMING_COLUMNS
from uavxai.cli import main
from uavxai.journal import JOURNAL

ROOT = Path(__file__).resolve().parents[1]
SCENARIO = str(ROOT / "scenarios" / "manoeuvring.yaml")
COMMAND = ["evaluate", SCENARIO, "--methods", "none,dqn", "--intruders", "3,6",
           "--dynamics", "kinematic", "--seed", "7"]  # fmt: skip


def _table(path: Path) -> list[dict]:
    """A CSV's rows without the columns no two runs share (planner times)."""
    with path.open() as f:
        rows = list(csv.DictReader(f))
    drop = set(TIMING_COLUMNS) | {"decision_ms_p50_ms"}
    return [{k: v for k, v in r.items() if k not in drop} for r in rows]


def _same_files(a: Path, b: Path) -> None:
    for name in ("episodes.csv", "results.csv"):
        assert _table(a / name) == _table(b / name), name


@pytest.fixture(scope="module")
def whole(tmp_path_factory) -> Path:
    """The campaign flown without interruption, 4 episodes per (method, count)."""
    out = tmp_path_factory.mktemp("whole") / "c"
    assert main([*COMMAND, "--episodes", "4", "--out", str(out)]) == 0
    return out


def _journaled(out: Path) -> int:
    try:
        return (out / JOURNAL).read_text().count("\n") - 1
    except FileNotFoundError:
        return 0


def test_a_campaign_killed_half_way_resumes_to_the_same_files(whole: Path, tmp_path) -> None:
    out = tmp_path / "c"
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    proc = subprocess.Popen(
        [sys.executable, "-m", "uavxai", *COMMAND, "--episodes", "4", "--out", str(out)],
        env=env, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        deadline = time.monotonic() + 300
        while _journaled(out) < 5 and proc.poll() is None and time.monotonic() < deadline:
            time.sleep(0.05)
        assert proc.poll() is None, "the campaign ended before it could be killed"
        proc.send_signal(signal.SIGKILL)
    finally:
        proc.wait(timeout=60)
    flown = _journaled(out)
    assert 5 <= flown < 16
    assert not (out / "results.csv").exists()  # killed: nothing but the journal was saved
    assert main([*COMMAND, "--episodes", "4", "--out", str(out), "--resume"]) == 0
    _same_files(whole, out)
    # the journal now holds every episode once
    rows = (out / JOURNAL).read_text().splitlines()[1:]
    tasks = [(r["method"], r["intruders"], r["episode"]) for r in map(json.loads, rows)]
    assert len(tasks) == len(set(tasks)) == 16


def test_a_torn_last_line_is_not_a_row_and_a_campaign_may_grow(whole: Path, tmp_path) -> None:
    out = tmp_path / "c"
    assert main([*COMMAND, "--episodes", "2", "--out", str(out)]) == 0
    with (out / JOURNAL).open("a") as f:
        f.write('{"method":"none","intruders":3,"episode":3,"outco')  # a kill mid-write
    assert main([*COMMAND, "--episodes", "4", "--out", str(out), "--resume"]) == 0
    _same_files(whole, out)


@pytest.mark.parametrize(
    ("change", "named"),
    [(["--seed", "8"], "seed"), (["--methods", "none"], "methods"),
     (["--dynamics", "jsbsim"], "dynamics"), (["--intruders", "3"], "intruders")],
)  # fmt: skip
def test_resuming_another_campaign_is_refused_naming_what_differs(
    tmp_path, capsys, change: list[str], named: str
) -> None:
    out = tmp_path / "c"
    assert main([*COMMAND, "--episodes", "1", "--out", str(out)]) == 0
    before = (out / JOURNAL).read_bytes()
    argv = [*COMMAND, "--episodes", "1", "--out", str(out), "--resume"]
    for flag_at in range(0, len(change), 2):
        flag, value = change[flag_at:flag_at + 2]
        argv[argv.index(flag) + 1] = value
    assert main(argv) == 2
    err = capsys.readouterr().err
    assert "journals another campaign" in err and named in err, err
    assert (out / JOURNAL).read_bytes() == before  # nothing flown, nothing written


def test_resume_needs_an_interrupted_campaign_folder(tmp_path, capsys) -> None:
    assert main([*COMMAND, "--episodes", "1", "--out", str(tmp_path / "none"), "--resume"]) == 2
    assert "does not exist" in capsys.readouterr().err
    assert not (tmp_path / "none").exists()
    plain = tmp_path / "plain"
    plain.mkdir()
    assert main([*COMMAND, "--episodes", "1", "--out", str(plain), "--resume"]) == 2
    assert "marker" in capsys.readouterr().err
    assert list(plain.iterdir()) == []
    assert main([*COMMAND, "--episodes", "1", "--out", str(plain), "--resume", "--force"]) == 2
    assert "give one of them" in capsys.readouterr().err


def test_the_digest_covers_the_bridge_and_aircraft_beside_the_package(tmp_path) -> None:
    """A source checkout keeps bridges/ and aircraft/ beside the package (the editable
    install maps them in): a change there is other code, as one inside the package is."""
    import importlib.util
    import shutil

    from uavxai.paths import aircraft_dir, installation_digest, source_digest

    package = Path(source_digest.__code__.co_filename).parent
    spec = importlib.util.find_spec("uavxai.bridges")
    bridges = Path(next(iter(spec.submodule_search_locations)))
    assert source_digest() == installation_digest(package, bridges, aircraft_dir())
    skip = shutil.ignore_patterns("__pycache__")
    copies = {name: tmp_path / name for name in ("pkg", "bridges", "aircraft")}
    for name, src in zip(copies, (package, bridges, aircraft_dir()), strict=True):
        shutil.copytree(src, copies[name], ignore=skip, symlinks=True)
    before = installation_digest(*copies.values())
    telemetry = copies["bridges"] / "telemetry.py"
    telemetry.write_text(telemetry.read_text() + "#")
    assert installation_digest(*copies.values()) != before
    # a wheel: the bridge inside the package is counted once, with the package
    inside = copies["pkg"] / "bridges"
    shutil.copytree(copies["bridges"], inside)
    wheel = installation_digest(copies["pkg"], inside, copies["aircraft"])
    assert len(wheel) == len(source_digest(copies["pkg"])) + 8
    telemetry = inside / "telemetry.py"
    telemetry.write_text(telemetry.read_text() + "#")
    assert installation_digest(copies["pkg"], inside, copies["aircraft"]) != wheel


def test_the_journal_names_the_code_that_flew_it(tmp_path, capsys) -> None:
    """Rows flown by other code (another commit of the same version) are not taken over:
    the journal's header carries a digest of uavxai's files, and a resume compares it."""
    import shutil

    from uavxai.paths import source_digest

    copy = tmp_path / "pkg"
    shutil.copytree(Path(source_digest.__code__.co_filename).parent, copy,
                    ignore=shutil.ignore_patterns("__pycache__"))  # fmt: skip
    before = source_digest(copy)
    assert source_digest(copy) == before  # the same files, the same digest
    (copy / "__pycache__").mkdir()
    (copy / "__pycache__" / "x.pyc").write_bytes(b"compiled")
    assert source_digest(copy) == before  # bytecode is not code
    mcts = copy / "avoidance" / "mcts.py"
    mcts.write_text(mcts.read_text() + "#")
    assert source_digest(copy) != before  # one character of one file

    out = tmp_path / "c"
    assert main([*COMMAND, "--episodes", "1", "--out", str(out)]) == 0
    lines = (out / JOURNAL).read_text().splitlines()
    header = json.loads(lines[0])
    assert header["versions"]["uavxai_sources"] == source_digest()
    header["versions"]["uavxai_sources"] = "0" * 16  # as if flown by other code
    (out / JOURNAL).write_text("\n".join([json.dumps(header), *lines[1:]]) + "\n")
    assert main([*COMMAND, "--episodes", "2", "--out", str(out), "--resume"]) == 2
    err = capsys.readouterr().err
    assert "journals another campaign" in err and "versions" in err, err
