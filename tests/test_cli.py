"""The command line around the work: output folders (marker, --force, lock), broken pipes,
short reports on stdout with the JSON in the output folder."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from uavxai import cli
from uavxai.cli import MARKER, main, prepare_out_dir
from uavxai.errors import UserError

pytestmark = pytest.mark.usefixtures("release_cli_locks")


REPO = Path(__file__).resolve().parents[1]
UAVXAI = [sys.executable, "-m", "uavxai"]

# A short real run: one head-on intruder, a random service search, no recording.
TINY = """\
name: tiny
seed: 1
ownship:
  start: {x: 200, y: 1000, h: 120, heading_deg: 90, speed_mps: 20}
  goal: [1800, 1000, 120]
service: {planner: random, steps: 5}
intruders:
  list:
    - {x: 800, y: 1000, h: 120, heading_deg: 270, speed_mps: 22}
avoidance: {planner: mcts_fast, max_steps: 15}
log: {rerun: false}
"""




@pytest.fixture(scope="module")
def tiny(tmp_path_factory: pytest.TempPathFactory) -> Path:
    folder = tmp_path_factory.mktemp("tiny")
    path = folder / "tiny.yaml"
    path.write_text(TINY)
    return path


@pytest.fixture(scope="module")
def run_dir(tiny: Path) -> Path:
    out = tiny.parent / "run"
    proc = subprocess.run(
        [*UAVXAI, "run", str(tiny), "--out", str(out)], capture_output=True, text=True
    )
    assert proc.returncode == 0, proc.stderr
    assert (out / "decisions.jsonl").stat().st_size > 0
    return out


# ----------------------------------------------------------------------------- output folders
def test_output_folder_is_marked_and_force_removes_only_in_marked_folders(tmp_path: Path) -> None:
    out = prepare_out_dir(tmp_path / "a" / "b", force=False)
    assert (out / MARKER).is_file()
    assert json.loads((out / MARKER).read_text())["pid"] == os.getpid()
    (out / "summary.json").write_text("{}")
    (out / "sub").mkdir()
    (out / "sub" / "x.csv").write_text("1")
    with pytest.raises(UserError, match="not empty.*--force"):
        prepare_out_dir(out, force=False)
    assert prepare_out_dir(out, force=True) == out
    assert sorted(p.name for p in out.iterdir()) == [MARKER]

    theirs = tmp_path / "theirs"
    theirs.mkdir()
    (theirs / "thesis.tex").write_text("precious")
    for force in (False, True, True):  # a refusal leaves no marker that would let --force in
        with pytest.raises(UserError, match="not written by uavxai" if force else "not empty"):
            prepare_out_dir(theirs, force=force)
        assert sorted(p.name for p in theirs.iterdir()) == ["thesis.tex"]
    assert (theirs / "thesis.tex").read_text() == "precious"

    empty = tmp_path / "empty"
    empty.mkdir()
    assert (prepare_out_dir(empty, force=True) / MARKER).is_file()  # an empty folder is fine


def test_force_never_empties_the_working_folder_home_or_root(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    work = tmp_path / "work" / "deeper"
    work.mkdir(parents=True)
    (work / "notes.txt").write_text("mine")
    (work / MARKER).write_text("")  # even a folder that looks like ours
    monkeypatch.chdir(work)
    for out in (Path("."), Path("./"), work, work.parent, Path("/"), Path.home(), Path("..")):
        with pytest.raises(UserError, match="refusing --force"):
            prepare_out_dir(out, force=True)
    scenario = str(REPO / "scenarios" / "demo.yaml")
    assert main(["service", scenario, "--planner", "random", "--out", ".", "--force"]) == 2
    assert "refusing --force" in capsys.readouterr().err
    assert (work / "notes.txt").read_text() == "mine"


def test_unwritable_or_odd_out_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = str(REPO / "scenarios" / "demo.yaml")
    a_file = tmp_path / "file"
    a_file.write_text("x")
    for out in (a_file, a_file / "sub", Path("/proc/uavxai-out")):
        assert main(["service", scenario, "--planner", "random", "--out", str(out)]) == 2
        err = capsys.readouterr().err
        assert "--out" in err and "Traceback" not in err and "internal error" not in err
    with pytest.raises(UserError, match="NUL"):
        prepare_out_dir(Path("a\x00b"), force=False)


def test_a_second_process_cannot_write_into_a_locked_folder(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Two runs into one new --out: the second one stops at once with exit 2."""
    out = tmp_path / "shared"
    holder = subprocess.Popen(
        [
            sys.executable, "-c",
            "import sys, time; from pathlib import Path; from uavxai.cli import prepare_out_dir;"
            f"prepare_out_dir(Path({str(out)!r}), False); print('locked', flush=True);"
            "sys.stdin.read()",
        ],
        stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True,
    )
    try:
        assert holder.stdout.readline().strip() == "locked"
        scenario = str(REPO / "scenarios" / "demo.yaml")
        for extra in ([], ["--force"]):
            argv = ["service", scenario, "--planner", "random", "--out", str(out), *extra]
            assert main(argv) == 2
            assert "another uavxai process" in capsys.readouterr().err
        assert sorted(p.name for p in out.iterdir()) == [MARKER]  # nothing of ours mixed in
    finally:
        holder.stdin.close()  # the holder reads stdin to its end, then exits
        holder.wait(timeout=30)
    # the holder has ended: its lock went with it, and the folder is ours to use
    assert prepare_out_dir(out, force=False) == out


# ------------------------------------------------------------------------------- broken pipes
def test_explain_into_a_closed_pipe_ends_quietly(run_dir: Path) -> None:
    """`uavxai explain RUN | head`: the reader goes away before uavxai writes."""
    for extra in ([], ["--decision", "0"]):
        proc = subprocess.Popen(
            [*UAVXAI, "explain", str(run_dir), *extra],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        )
        proc.stdout.close()  # closed before the interpreter has even started: EPIPE for sure
        err = proc.stderr.read().decode()
        assert proc.wait(timeout=60) == 141
        assert "Traceback" not in err and "BrokenPipe" not in err and "internal error" not in err


def test_explain_through_head(run_dir: Path) -> None:
    proc = subprocess.run(
        f"{sys.executable} -m uavxai explain {run_dir} --decision 0 | head -n 1",
        shell=True, capture_output=True, text=True,
    )
    assert proc.stdout.startswith("Decision 0")
    assert "Traceback" not in proc.stderr


# ----------------------------------------------------------------------------- short reports
def test_service_prints_a_short_table_and_writes_the_json(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "svc"
    assert main(["service", str(tiny), "--out", str(out)]) == 0
    text = capsys.readouterr().out
    summary = json.loads((out / "summary.json").read_text())
    assert "sum_rate_bps" in summary and len(summary["rate_bps"]) == 10
    lines = text.splitlines()
    assert len(lines) <= 35, text
    assert not text.lstrip().startswith("{")
    assert str(out / "summary.json") in text
    # labelled values with units, not the JSON's raw keys (issue 30)
    assert "sum_rate_bps" not in text and "e+0" not in text
    assert f"sum rate           {summary['sum_rate_bps'] / 1e6:.2f} Mbit/s" in text
    assert f"users at QoS       {summary['qos_satisfied']} of 10" in text
    x, y, h = summary["service_point"]
    assert f"x {x:.0f} m, y {y:.0f} m, height {h:.0f} m" in text


def test_report_table_keeps_to_its_row_limit(tmp_path: Path, capsys) -> None:
    report = {f"k{i}": float(i) for i in range(100)} | {"nested": {"a": 1, "b": [1, 2]}}
    cli.print_report("t", report, tmp_path / "r.json", max_rows=10)
    text = capsys.readouterr().out
    assert "k9 " in text and "k10 " not in text and "92 more in r.json" in text


@pytest.mark.slow
def test_train_prints_a_short_table_and_writes_the_json(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:

    out = tmp_path / "train"
    argv = ["train", str(tiny), "--stage", "service", "--algo", "dqn", "--episodes", "2"]
    assert main([*argv, "--out", str(out)]) == 0
    text = capsys.readouterr().out
    report = json.loads((out / "train_report.json").read_text())
    assert report["algo"] == "dqn" and (out / "model.pt").is_file()
    assert len(text.splitlines()) <= 35 and not text.lstrip().startswith("{")
    assert "train_report.json" in text


def test_train_reaches_every_trainer_and_refuses_an_algo_of_another_stage(
    tiny: Path, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """One command trains every learned planner (issue 29): the universal service model too,
    whose model.pt the service stage loads; an algorithm another stage trains is exit 2."""
    from uavxai.service import universal

    out = tmp_path / "universal"
    argv = ["train", str(tiny), "--stage", "universal", "--algo", "dqn", "--episodes", "1"]
    assert main([*argv, "--out", str(out)]) == 0
    net, info = universal.load(out / "model.pt")
    assert info["algo"] == "dqn" and not net.dueling
    capsys.readouterr()
    bad = ["train", str(tiny), "--stage", "universal", "--algo", "safe_dqn"]
    assert main([*bad, "--out", str(tmp_path / "bad")]) == 2
    err = capsys.readouterr().err
    assert "--algo safe_dqn" in err and "allowed: d3qn, dqn" in err and "Traceback" not in err


def test_force_never_empties_a_folder_without_a_marker(tmp_path: Path) -> None:
    """Files named like uavxai's outputs (a user's PNGs, a summary.json) do not make a folder
    uavxai's: without the marker, --force is refused and every file stays."""
    for name, files in (
        ("photos", ("holiday.png", "cat.png")),
        ("summary", ("summary.json",)),
        ("old-demo", ("summary.json", "trajectory.csv", "decisions.jsonl", "run.rrd")),
    ):
        folder = tmp_path / name
        folder.mkdir()
        for f in files:
            (folder / f).write_text(f"the user's {f}")
        with pytest.raises(UserError, match="refusing --force.*no .uavxai-run marker"):
            prepare_out_dir(folder, force=True)
        assert sorted(p.name for p in folder.iterdir()) == sorted(files)
        for f in files:
            assert (folder / f).read_text() == f"the user's {f}"
