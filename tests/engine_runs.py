"""One scenario flown by `uavxai run` and by `uavxai evaluate --dynamics jsbsim`, for the tests
that check both fly the same episode."""

from __future__ import annotations

import json
from pathlib import Path

import yaml

from uavxai.cli import main


def run_and_evaluate(tmp_path: Path, scenario: dict) -> tuple[dict, dict]:
    """(run's summary.json, evaluate's one episodes.csv row) of ``scenario`` (mcts, its
    intruder count, one episode on its seed)."""
    path = tmp_path / f"{scenario['name']}.yaml"
    path.write_text(yaml.safe_dump(scenario))
    assert main(["run", str(path), "--out", str(tmp_path / "run")]) == 0
    n = str(scenario["intruders"]["count"])
    assert main(
        ["evaluate", str(path), "--methods", "mcts", "--intruders", n, "--episodes", "1",
         "--dynamics", "jsbsim", "--out", str(tmp_path / "ev")]
    ) == 0  # fmt: skip
    run = json.loads((tmp_path / "run" / "summary.json").read_text())
    header, row = (tmp_path / "ev" / "episodes.csv").read_text().splitlines()[:2]
    return run, dict(zip(header.split(","), row.split(","), strict=True))


def flown_twice(scenario, method: str, n_intruders: int, seed: int) -> tuple[dict, dict]:
    """One kinematic campaign episode of ``scenario`` flown twice by ``method``: both
    episodes.csv rows, less the timings (which differ run to run)."""
    from uavxai.campaign import run_campaign_episode

    timing = ("decision_ms", "decision_ms_p50")
    a, b = (run_campaign_episode(scenario, method, n_intruders, seed, "kinematic")
            for _ in range(2))  # fmt: skip
    return ({k: v for k, v in a.items() if k not in timing},
            {k: v for k, v in b.items() if k not in timing})  # fmt: skip
