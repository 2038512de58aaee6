"""What a new user meets first (issue 30): help for every option, the shipped scenarios
listed, the service stage in words and units, a run's quick-look plot, its printed summary
and a command the user can run to explain it."""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
from pathlib import Path

import pytest
from test_cli import TINY  # one head-on intruder, a few decisions, no recording

from uavxai.cli import build_parser, main
from uavxai.paths import scenario_catalogue, shipped_scenarios
from uavxai.vocabulary import AVOIDANCE_PLANNERS

pytestmark = pytest.mark.usefixtures("release_cli_locks")


def _subcommands() -> dict[str, argparse.ArgumentParser]:
    sub = next(a for a in build_parser()._actions if isinstance(a, argparse._SubParsersAction))
    return dict(sub.choices)


def test_every_option_of_every_subcommand_has_help_and_its_default() -> None:
    commands = _subcommands()
    assert {"run", "evaluate", "merge", "service", "explain", "scenarios"} <= set(commands)
    for name, parser in commands.items():
        text = " ".join(parser.format_help().split())
        for action in parser._actions:
            if isinstance(action, argparse._HelpAction):
                continue
            what = f"uavxai {name} {action.option_strings or action.dest}"
            assert action.help and action.help.strip(), f"{what}: no help text"
            if action.default not in (None, False):
                assert f"(default: {action.default})" in text, f"{what}: default not shown"


def test_the_methods_list_never_breaks_inside_a_name() -> None:
    """A narrow terminal wraps the help at spaces only: every method's name stays whole."""
    env = {**os.environ, "COLUMNS": "46"}
    proc = subprocess.run(
        [sys.executable, "-m", "uavxai", "evaluate", "--help"],
        capture_output=True, text=True, env=env, check=True,
    )  # fmt: skip
    words = set(proc.stdout.replace(",", " ").split())
    assert set(AVOIDANCE_PLANNERS) <= words, proc.stdout


def test_scenarios_lists_every_shipped_one_with_its_description(
    capsys: pytest.CaptureFixture[str],
) -> None:
    assert main(["scenarios"]) == 0
    out = capsys.readouterr().out
    rows = scenario_catalogue()
    assert [name for name, _, _ in rows] == shipped_scenarios() and rows
    for name, about, path in rows:
        assert path.is_file() and path.stem == name
        first_comment = path.read_text().splitlines()[0].lstrip("# ")
        assert about[:40] == first_comment[:40]  # the file's own first words
        assert f"{name}  " in out and about in out and str(path) in out


def test_the_grid_search_shows_its_progress(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A small lattice (5 x 5 x 6 points) so the exact search takes seconds; off a terminal
    the bar says its last line when the search completes."""
    scenario = tmp_path / "g.yaml"
    scenario.write_text(
        "name: grid\ncomms:\n  users:\n    count: 4\n    region: {x: [900, 1100], y: [900, 1100]}\n"
        "service: {step_m: 50}\nworld: {h: [50, 300]}\n"
    )
    assert main(["service", str(scenario), "--planner", "grid", "--out", str(tmp_path / "o")]) == 0
    captured = capsys.readouterr()
    summary = json.loads((tmp_path / "o" / "summary.json").read_text())
    n = summary["lattice_points"]
    assert f"grid search: {n}/{n} (100 %)" in captured.err
    assert f"grid search        {n} lattice points" in captured.out


def test_a_run_plots_prints_its_safety_and_a_runnable_explain_command(tmp_path: Path) -> None:
    """`run` started by the path of the venv's script (not on PATH, as after `make demo`)
    writes run.png, prints NMAC and the trust figure, and tells the user the command to run."""
    script = Path(sys.executable).with_name("uavxai")
    if not script.is_file():
        pytest.skip("the uavxai console script is not installed beside this interpreter")
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text(TINY)
    out = tmp_path / "run"
    env = {**os.environ, "PATH": "/usr/bin:/bin"}  # the venv's bin is not on PATH
    proc = subprocess.run(
        [str(script), "run", str(scenario), "--out", str(out)],
        capture_output=True, text=True, env=env, cwd=tmp_path,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    png = (out / "run.png").read_bytes()
    assert png.startswith(b"\x89PNG\r\n\x1a\n") and len(png) > 20_000
    summary = json.loads((out / "summary.json").read_text())
    assert summary["failure"] is None and summary["intruders_lost"] == []
    text = " ".join(proc.stderr.split())
    p95 = summary["trust"]["separation_error_m"]["p95"]
    assert f"NMAC {'yes' if summary['nmac'] else 'no'}" in text
    assert f"p95 {p95:.0f} m" in text
    hint = f"{script} explain {out} --decision 0"
    assert hint in text
    again = subprocess.run(hint.split(), capture_output=True, text=True, env=env)
    assert again.returncode == 0 and again.stdout.startswith("Decision 0")


def test_explain_and_scenarios_do_not_load_the_simulator(tmp_path: Path) -> None:
    """`explain` and `scenarios` read files: building the command line must not import the
    dynamics, JSBSim, MAVLink or torch (they made `explain` of one decision take seconds)."""
    decision = {"t": 0.0, "action": {"bank_cmd_rad": 0.0, "accel_mps2": 0.0}, "children": [],
                "explanation": "held", "ms": 1.0}  # fmt: skip
    (tmp_path / "decisions.jsonl").write_text(json.dumps(decision) + "\n")
    heavy = ("uavxai.sim.build", "jsbsim", "pymavlink", "torch")
    for argv in (["explain", str(tmp_path), "--decision", "0"], ["scenarios"]):
        code = (
            "import sys\nfrom uavxai.cli import main\n"
            f"rc = main({argv!r})\n"
            f"print(rc, [m for m in {heavy!r} if m in sys.modules])"
        )
        proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert proc.stdout.splitlines()[-1] == "0 []", (argv, proc.stdout, proc.stderr)
