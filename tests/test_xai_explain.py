"""Explanations in words, and `uavxai explain` on a decisions.jsonl of real decisions."""

from __future__ import annotations

import json

import pytest

from uavxai.avoidance import Intruder, MCTSPlanner, Ownship, PlannerConfig
from uavxai.cli import main
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.sim.build import run_kinematic as run_episode
from uavxai.xai.explain import explain_command, is_avoidance

HEAD_ON = (Ownship(1000, 400, 120, 20, 0.0), [Intruder(7, 1000, 800, 120, 0.0, -20.0)])


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A run folder whose decisions.jsonl holds a real episode's decisions."""
    sc = default_scenario(
        "explain-test",
        ownship={"start": {"x": 1000, "y": 300, "h": 120, "heading_deg": 0, "speed_mps": 20}},
        intruders={"list": [{"x": 1000, "y": 800, "h": 120, "heading_deg": 180, "speed_mps": 20}]},
        avoidance={"mcts": {"simulations": 60, "depth": 3}},
        surveillance={"model": "truth"},
    )
    result = run_episode("mcts", sc, seed=0, keep_decisions=True)
    folder = tmp_path_factory.mktemp("run")
    with (folder / "decisions.jsonl").open("w") as f:
        for record in result.records:
            f.write(json.dumps(record) + "\n")
    return folder, result


def test_sentence_names_the_threat_the_choice_and_the_support():
    own, intruders = HEAD_ON
    d = MCTSPlanner(PlannerConfig(seed=0)).plan(own, intruders, (1000, 1800, 120))
    assert d.explanation.startswith("banked ")
    assert "holding bank and speed meets intruder 7 at" in d.explanation
    assert f"{round(100 * d.confidence)}% of simulations agree" in d.explanation
    runner = max((c for c in d.children if c.action != d.action), key=lambda c: (c.visits, c.q))
    assert d.counterfactual.startswith("why not ")
    assert f"{runner.q:.3f}" in d.counterfactual
    assert is_avoidance(d.children, d.action, d.d_min_m)


def test_one_decision_in_full(run_dir):
    folder, result = run_dir
    n = len(result.records)
    text = explain_command(folder, 0)
    first = result.records[0]
    assert text.startswith(f"Decision 0 of {n} at t = 0.0 s (mcts")
    assert first["explanation"] in text
    assert first["counterfactual"].removeprefix("why not ") in text
    assert text.count("\n  * ") == 1  # the chosen action is marked once in the table
    for c in first["children"]:
        assert c["action"]["name"] in text
    last = explain_command(folder, -1)
    assert last.startswith(f"Decision {n - 1} of {n}")


def test_overview_counts_and_finds_the_tightest(run_dir):
    folder, result = run_dir
    text = explain_command(folder, None)
    n = len(result.records)
    assert text.startswith(f"{n} decisions; ")
    seps = [r["predicted_min_separation_m"] for r in result.records]
    tightest = min(range(n), key=lambda i: seps[i])
    assert f"Tightest: decision {tightest}, predicted {seps[tightest]:.0f} m" in text
    avoided = int(text.split("; ")[1].split(" ")[0])
    assert 1 <= avoided <= n  # the head-on encounter is avoided at least once


def test_bad_input_is_a_clear_error(run_dir, tmp_path):
    folder, result = run_dir
    n = len(result.records)
    with pytest.raises(UserError, match=rf"between 0 and {n - 1}"):
        explain_command(folder, n)
    with pytest.raises(UserError, match="no such run folder"):
        explain_command(tmp_path / "missing", None)
    with pytest.raises(UserError, match="decisions.jsonl: not found"):
        explain_command(tmp_path, None)
    bad = tmp_path / "bad"
    bad.mkdir()
    lines = (folder / "decisions.jsonl").read_text().splitlines()
    (bad / "decisions.jsonl").write_text("\n".join([lines[0], "{not json", *lines[1:]]) + "\n")
    with pytest.raises(UserError, match="line 2: not valid JSON"):
        explain_command(bad, 0)


def test_cli_explain(run_dir, tmp_path, capsys):
    folder, _ = run_dir
    assert main(["explain", str(folder), "--decision", "0"]) == 0
    assert "Decision 0 of" in capsys.readouterr().out
    assert main(["explain", str(tmp_path / "nope")]) == 2
    err = capsys.readouterr().err
    assert "no such run folder" in err and "Traceback" not in err


def test_equal_values_are_not_called_lower():
    """Near the goal every line reaches it (Q 1.000 for all): the sentence must say the
    actions tie and what decided, not that holding course "scores lower"."""
    own = Ownship(1000, 1000, 120, 20, 0.0)
    not_hold = 0
    for seed in range(8):
        d = MCTSPlanner(PlannerConfig(seed=seed, depth=3)).plan(own, [], (1000, 1090, 120))
        assert {f"{c.q:.3f}" for c in d.children} == {"1.000"}  # the situation under test
        assert "scores lower" not in d.explanation
        assert "as good (Q 1.000 both)" in d.counterfactual
        if d.action != 4:
            not_hold += 1
            assert "holding bank and speed is as good (Q 1.000), " in d.explanation
            chosen = next(c for c in d.children if c.action == d.action)
            hold = next(c for c in d.children if c.action == 4)
            said_more = "this one had more simulations" in d.explanation
            assert said_more == (chosen.visits > hold.visits)  # true to the tree
    assert not_hold  # the tie-break picked something other than holding at least once


def _child(action: int, visits: int, q: float):
    from uavxai.avoidance.types import ChildStats

    return ChildStats(action, 0.0, 0.0, visits, q, 300.0, None, None, "")


def test_a_visit_tie_is_not_called_more_simulations():
    from uavxai.avoidance.types import Decision

    chosen, hold = _child(0, 20, 0.80001), _child(4, 20, 0.80000)
    d = Decision(0.0, 1.0, 0, [chosen, hold], planner="mcts")
    assert "more simulations" not in d.explanation
    assert "as many simulations (20 each)" in d.explanation
    d = Decision(0.0, 1.0, 0, [_child(0, 25, 0.8), _child(4, 20, 0.8)], planner="mcts")
    assert "more simulations (25 against 20)" in d.explanation


def test_the_plan_label_is_the_branch_minimum_and_its_intruder():
    from uavxai.avoidance.types import ChildStats, Decision
    from uavxai.recording.recorder import _plan_label

    kids = [ChildStats(a, 0.0, 0.0, 10, 0.5, 80.0 + a, a % 2, 5.0, "") for a in range(9)]
    d = Decision(0.0, 0.0, 3, kids, predicted_min_separation_m=400.0, planner="mcts")
    # the one-period prediction (400 m) is not what the drawn branch keeps (83 m from row 1)
    assert _plan_label(d, ["intruder-7", "intruder-9"]) == "plan: 83 m from intruder-9"


def test_a_rejected_option_with_the_higher_q_is_not_called_lower():
    from uavxai.avoidance.types import Decision

    d = Decision(0.0, 1.0, 0, [_child(0, 30, 0.70), _child(4, 10, 0.75)], planner="mcts")
    assert "scores lower" not in d.explanation
    assert "has the higher Q (0.750 against 0.700) but fewer simulations (10 against 30)" in (
        d.explanation
    )
