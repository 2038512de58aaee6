"""Hostile output folders and campaign files (issue 30, "Hostile inputs"): each case ends with
exit 2 and one paragraph naming what is wrong and what is allowed, no traceback, and nothing
outside ``--out`` touched."""

from __future__ import annotations

import csv
import json
import os
import shutil
import subprocess
from pathlib import Path

import pytest

from uavxai import cli
from uavxai.cli import MARKER, main
from uavxai.outputs import write_output

pytestmark = pytest.mark.usefixtures("release_cli_locks")


@pytest.fixture(scope="module")
def campaign(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """One real, tiny campaign (`uavxai evaluate`, kinematic, one episode), copied by tests."""
    root = tmp_path_factory.mktemp("campaign")
    scenario = root / "s.yaml"
    scenario.write_text("name: hostile-merge\nownship:\n  goal: [900, 900, 120]\n")
    out = root / "campaign"
    argv = ["evaluate", str(scenario), "--methods", "none,mvp", "--intruders", "3",
            "--episodes", "2", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    for lock in cli._HELD_LOCKS.values():
        lock.close()
    cli._HELD_LOCKS.clear()
    return out


def _copy(campaign: Path, to: Path) -> Path:
    shutil.copytree(campaign, to)
    return to


def _snapshot(root: Path, skip: Path | None = None) -> dict[str, tuple[str, bytes | str]]:
    """Every path under root (links not followed) with its content, except under ``skip``."""
    seen = {}
    for dirpath, dirnames, filenames in os.walk(root):
        for name in dirnames + filenames:
            p = Path(dirpath) / name
            if skip is not None and (p == skip or skip in p.parents):
                continue
            if p.is_symlink():
                seen[str(p)] = ("link", os.readlink(p))
            elif p.is_file():
                seen[str(p)] = ("file", p.read_bytes())
            else:
                seen[str(p)] = ("dir", "")
    return seen


def _refused(capsys: pytest.CaptureFixture[str], *words: str) -> str:
    err = capsys.readouterr().err
    assert err.startswith("uavxai: error: "), err
    assert "Traceback" not in err and "internal error" not in err, err
    assert len(err.strip().splitlines()) == 1, err  # one paragraph
    for w in words:
        assert w in err, f"{w!r} not in {err}"
    return err


# ---------------------------------------------------------------- 1. links in an output folder
@pytest.mark.parametrize("force", [False, True])
def test_symlinked_marker_never_overwrites_a_file_outside_out(
    tmp_path: Path, campaign: Path, capsys: pytest.CaptureFixture[str], force: bool
) -> None:
    src = _copy(campaign, tmp_path / "campaign")
    precious = tmp_path / "precious.txt"
    precious.write_text("the user's own words\n")
    trap = tmp_path / "trap"
    trap.mkdir()
    (trap / MARKER).symlink_to("../precious.txt")
    before = _snapshot(tmp_path)
    argv = ["merge", str(src), "--out", str(trap)] + (["--force"] if force else [])
    assert main(argv) == 2
    _refused(capsys, "symbolic link", str(trap), "never follows links")
    assert precious.read_text() == "the user's own words\n"
    assert _snapshot(tmp_path) == before  # nothing touched, the link itself left in place


def test_marker_that_is_a_fifo_is_refused_not_opened(
    tmp_path: Path, campaign: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _copy(campaign, tmp_path / "campaign")
    out = tmp_path / "out"
    out.mkdir()
    os.mkfifo(out / MARKER)
    assert main(["merge", str(src), "--out", str(out)]) == 2
    _refused(capsys, "not a plain file")
    # a source whose marker is a FIFO: refused, not read (which would block for ever)
    (src / MARKER).unlink()
    os.mkfifo(src / MARKER)
    assert main(["merge", str(src), "--out", str(tmp_path / "fresh")]) == 2
    _refused(capsys, str(src / MARKER), "plain file")
    assert not (tmp_path / "fresh").exists()


def test_force_removes_links_in_a_marked_folder_not_what_they_point_to(
    tmp_path: Path, campaign: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _copy(campaign, tmp_path / "campaign")
    precious = tmp_path / "precious"
    precious.mkdir()
    (precious / "results.csv").write_text("mine\n")
    out = tmp_path / "out"
    assert main(["merge", str(src), "--out", str(out)]) == 0
    cli._HELD_LOCKS.pop(out.resolve()).close()
    (out / "results.csv").unlink()
    (out / "results.csv").symlink_to(precious / "results.csv")
    (out / "linked-folder").symlink_to(precious)
    assert main(["merge", str(src), "--out", str(out), "--force"]) == 0
    assert (precious / "results.csv").read_text() == "mine\n"
    assert not (out / "results.csv").is_symlink() and not (out / "linked-folder").exists()


def test_an_output_written_where_a_link_was_planted_replaces_the_link(tmp_path: Path) -> None:
    """write_output renames a whole temporary file over the target: a link planted there after
    the folder was prepared is replaced, and the file it pointed to keeps its content."""
    precious = tmp_path / "precious.txt"
    precious.write_text("keep\n")
    out = tmp_path / "out"
    out.mkdir()
    (out / "summary.json").symlink_to(precious)
    write_output(out / "summary.json", "{}\n")
    assert precious.read_text() == "keep\n"
    assert not (out / "summary.json").is_symlink()
    assert (out / "summary.json").read_text() == "{}\n"
    assert sorted(p.name for p in out.iterdir()) == ["summary.json"]  # no temporary left


# ------------------------------------------------------------ 2. --force without a marker
def test_merge_force_into_a_folder_of_pngs_without_a_marker_is_refused(
    tmp_path: Path, campaign: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    src = _copy(campaign, tmp_path / "campaign")
    photos = tmp_path / "photos"
    photos.mkdir()
    (photos / "goal_rate.png").write_bytes(b"\x89PNG the user's")
    (photos / "summary.json").write_text('{"mine": true}')
    before = _snapshot(tmp_path)
    assert main(["merge", str(src), "--out", str(photos), "--force"]) == 2
    _refused(capsys, "refusing --force", "no .uavxai-run marker", str(photos))
    assert _snapshot(tmp_path) == before


# ------------------------------------------------------------------- 5. forged campaign files
def _forge(src: Path, column: str, value: str) -> None:
    """Set ``column`` of the first row of src/episodes.csv to ``value`` (text, as forged)."""
    with (src / "episodes.csv").open(newline="") as f:
        reader = csv.DictReader(f)
        columns, rows = list(reader.fieldnames or []), list(reader)
    rows[0][column] = value
    with (src / "episodes.csv").open("w", newline="") as f:
        w = csv.DictWriter(f, fieldnames=columns)
        w.writeheader()
        w.writerows(rows)


@pytest.mark.parametrize(
    ("column", "value", "allowed"),
    [
        ("steps", "-1e308", "a whole number from 0"),
        ("steps", "inf", "a whole number from 0"),
        ("steps", "12.5", "a whole number from 0"),
        ("nmac", "inf", "0 or 1"),
        ("nmac", "7", "0 or 1"),
        ("intruders", "1e308", "a whole number from 0"),
        ("seed", "-1", "a whole number from 0"),
        ("outcome", "teleported", "one of goal, completed, collision"),
        ("min_separation_m", "-5", "a distance >= 0"),
        ("min_separation_m", "nan", "a distance >= 0"),
        ("flight_time_s", "-inf", "a time >= 0"),
        ("decision_ms_p50", "nan", "a time >= 0"),
        ("goal_x", "inf", "a coordinate"),
        ("method", "=HYPERLINK(\"http://evil\",\"x\")", "a planner name, one of mcts"),
        ("method", "none ", "a planner name"),
    ],
)
def test_merge_refuses_forged_numbers_and_names(
    tmp_path: Path, campaign: Path, capsys: pytest.CaptureFixture[str], column: str, value: str,
    allowed: str,
) -> None:
    src = _copy(campaign, tmp_path / "campaign")
    _forge(src, column, value)
    out = tmp_path / "out"
    assert main(["merge", str(src), "--out", str(out)]) == 2
    _refused(capsys, str(src / "episodes.csv"), "line 2", column, allowed)
    assert not out.exists()  # the refused merge leaves no folder behind


def test_merge_of_a_real_campaign_keeps_its_numbers(tmp_path: Path, campaign: Path) -> None:
    """The checks refuse only what a campaign never writes: 'inf' separation (no intruder
    met), empty timing and goal are kept, and numbers are written back as numbers."""
    src = _copy(campaign, tmp_path / "campaign")
    _forge(src, "min_separation_m", "inf")
    _forge(src, "decision_ms_p50", "")
    out = tmp_path / "out"
    assert main(["merge", str(src), "--out", str(out)]) == 0
    with (out / "episodes.csv").open() as f:
        merged = list(csv.DictReader(f))
    with (campaign / "episodes.csv").open() as f:
        original = list(csv.DictReader(f))
    assert merged[0]["min_separation_m"] == "inf" and merged[0]["decision_ms_p50"] == ""
    for a, b in zip(merged[1:], original[1:], strict=True):
        assert a == b


def test_csv_cells_that_a_spreadsheet_would_run_are_made_inert(tmp_path: Path) -> None:
    from uavxai.campaign import write_csv

    path = tmp_path / "x.csv"
    cells = ["=1+1", "+cmd", "-2+3", "@SUM(A1)", "\tx", "-12.5", "-inf", "none", 3, -4.0]
    write_csv(path, [str(i) for i in range(len(cells))], [{str(i): c for i, c in enumerate(cells)}])
    rows = list(csv.reader(path.open()))
    written = rows[1]
    assert written[:5] == ["'=1+1", "'+cmd", "'-2+3", "'@SUM(A1)", "'\tx"]
    assert written[5:] == ["-12.5", "-inf", "none", "3", "-4"]  # numbers stay numbers


@pytest.mark.parametrize("argv", [["--help"], ["evaluate", "--help"], ["--version"], ["-h"],
                                  ["evaluate", "--bogus"], "not a list", []])  # fmt: skip
def test_merge_refuses_a_source_marker_that_records_no_campaign(
    tmp_path: Path, campaign: Path, capsys: pytest.CaptureFixture[str], argv
) -> None:
    """Before: a recorded `--help` made merge print its help and exit 0, writing nothing."""
    src = _copy(campaign, tmp_path / "campaign")
    marker = json.loads((src / MARKER).read_text())
    marker["argv"] = argv
    (src / MARKER).write_text(json.dumps(marker))
    out = tmp_path / "out"
    assert main(["merge", str(src), "--out", str(out)]) == 2
    assert capsys.readouterr().out == ""  # no help printed
    main(["merge", str(src), "--out", str(out)])
    _refused(capsys, str(src / MARKER))
    assert not out.exists()


# ------------------------------------------------------------------------------ 6. disk full
@pytest.fixture
def tiny_disk(tmp_path: Path):
    """A 64 kB tmpfs (needs root and mount); skipped with the reason otherwise."""
    disk = tmp_path / "disk"
    disk.mkdir()
    if os.geteuid() != 0 or shutil.which("mount") is None:
        pytest.skip("a tiny tmpfs needs root and mount(8)")
    proc = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(disk)],
                          capture_output=True, text=True)  # fmt: skip
    if proc.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here: {proc.stderr.strip()}")
    try:
        yield disk
    finally:
        for lock in cli._HELD_LOCKS.values():
            lock.close()
        cli._HELD_LOCKS.clear()
        subprocess.run(["umount", str(disk)], check=False)


def test_a_full_disk_says_no_space_left_and_marks_the_folder_incomplete(
    tmp_path: Path, campaign: Path, tiny_disk: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before: "internal error ... a bug" and a 0-byte plot beside whole CSVs."""
    src = _copy(campaign, tmp_path / "campaign")
    out = tiny_disk / "merged"
    before = _snapshot(tmp_path, skip=tiny_disk)
    assert main(["merge", str(src), "--out", str(out)]) == 2
    err = _refused(capsys, f"no space left on {out}", "incomplete")
    assert "bug" not in err
    marker = json.loads((out / MARKER).read_text())
    assert "no space left" in marker["incomplete"]
    for p in out.iterdir():  # every file there is whole: no 0-byte plot, no temporary
        assert not p.name.endswith(".part"), p
        assert p.stat().st_size > 0, p
    with (out / "episodes.csv").open() as f:
        assert len(list(csv.DictReader(f))) == 4  # the CSVs fitted, and are whole
    assert _snapshot(tmp_path, skip=tiny_disk) == before


def test_a_full_disk_while_merge_copies_a_fleet_run_says_no_space_left(
    tmp_path: Path, tiny_disk: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A fleet source (round 12's rows; episode 0's run folder holding its summary and a
    200 kB trajectory.csv) merged onto a 64 kB disk: "no space left" naming the file (copytree
    turned it into "internal error"), the run folder's part copied removed, the marker saying
    incomplete; the source untouched."""
    from uavxai.campaign.fleet import episode_folder

    src = tmp_path / "fleet"
    src.mkdir()
    rows = Path(__file__).resolve().parents[1] / "docs" / "results" / "fleet"
    shutil.copy(rows / "round12_seeds60-64_episodes.csv", src / "fleet_episodes.csv")
    run = episode_folder(src, "mcts", 20, 0)
    run.mkdir(parents=True)
    summary = {"scenario": "fleet-mission", "dynamics": "jsbsim", "seed": 60,
               "avoidance_planner": "mcts", "intruders": 22, "fleet": [{}, {}, {}]}  # fmt: skip
    (run / "summary.json").write_text(json.dumps(summary))
    (run / "trajectory.csv").write_text("t,id,x,y,h\n" + "0.0,ownship-0,1.0,2.0,3.0\n" * 8000)
    before = _snapshot(tmp_path, skip=tiny_disk)
    out = tiny_disk / "merged"
    assert main(["merge", str(src), "--out", str(out)]) == 2
    err = _refused(capsys, "no space left on", "trajectory.csv", "incomplete")
    assert "bug" not in err
    assert "no space left" in json.loads((out / MARKER).read_text())["incomplete"]
    assert not episode_folder(out, "mcts", 20, 0).exists()
    assert _snapshot(tmp_path, skip=tiny_disk) == before


def test_an_unwritable_output_is_a_clear_error_not_a_bug(tmp_path: Path) -> None:
    """The same error path without a tiny disk: a folder where an output file goes."""
    from uavxai.outputs import OutputError

    out = tmp_path / "out"
    (out / "results.csv").mkdir(parents=True)
    with pytest.raises(OutputError, match="cannot write .*results.csv") as err:
        write_output(out / "results.csv", "a,b\n")
    assert err.value.folder == out
    assert sorted(p.name for p in out.iterdir()) == ["results.csv"]  # no temporary left


# ------------------------------------------------------- 8. a refused command leaves nothing
def test_a_rejected_evaluate_leaves_no_folder_nor_marker(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """evaluate refuses a scenario with intruders.list after the output folder is prepared:
    the folder it created goes again; a folder that was there stays, without our marker."""
    scenario = tmp_path / "listed.yaml"
    scenario.write_text("name: listed\nintruders: {list: [{x: 500, y: 500, h: 120, "
                        "heading_deg: 0, speed_mps: 20}]}\n")  # fmt: skip
    argv = ["evaluate", str(scenario), "--methods", "none", "--intruders", "3", "--episodes", "1"]
    new = tmp_path / "a" / "new"
    assert main([*argv, "--out", str(new)]) == 2
    _refused(capsys, "intruders.list")
    assert not new.exists() and (tmp_path / "a").is_dir()  # only what it created is removed
    there = tmp_path / "there"
    there.mkdir()
    assert main([*argv, "--out", str(there)]) == 2
    _refused(capsys, "intruders.list")
    assert there.is_dir() and list(there.iterdir()) == []
    # a folder of an earlier run keeps its marker (it was not this command's)
    old = tmp_path / "old"
    old.mkdir()
    (old / MARKER).write_text('{"uavxai": "0", "pid": 1, "argv": ["run", "x"]}\n')
    assert main([*argv, "--out", str(old), "--force"]) == 2
    _refused(capsys, "intruders.list")
    assert sorted(p.name for p in old.iterdir()) == [MARKER]
