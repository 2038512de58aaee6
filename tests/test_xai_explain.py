"""Explanations in words, and `uavxai explain` on a decisions.jsonl of real decisions."""

from __future__ import annotations

import json

import pytest

from uavxai.avoidance import Intruder, MCTSPlanner, Ownship, PlannerConfig
from uavxai.cli import main
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.sim.build import run_kinematic as run_episode
from uavxai.xai.explain import decision_record, explain_command, is_avoidance

HEAD_ON = (Ownship(1000, 400, 120, 20, 0.0), [Intruder(7, 1000, 800, 120, 0.0, -20.0)])


@pytest.fixture(scope="module")
def run_dir(tmp_path_factory):
    """A run folder whose decisions.jsonl holds a real episode's decisions."""
    sc = default_scenario(
        "explain-test",
        ownship={"start": {"x": 1000, "y": 300, "h": 120, "heading_deg": 0, "speed_mps": 20}},
        # 400 m apart, closing at 40 m/s: holding meets it within the 12 s search horizon
        intruders={"list": [{"x": 1000, "y": 700, "h": 120, "heading_deg": 180, "speed_mps": 20}]},
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
    assert "holding bank and speed meets intruder 7 in " in d.explanation
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
    # "steered away from a predicted conflict": holding's line conflicts, the chosen one's not
    expected = 0
    for r in result.records:
        kids = {c["action"]["index"]: c for c in r["children"]}
        hold, chosen = kids[4], kids[r["action"]["index"]]
        other = chosen["flies"] != hold["flies"]
        expected += hold["meets"] is not None and chosen["meets"] is None and other
    assert avoided == expected


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


def test_the_best_value_backup_is_explained_by_its_q_not_its_simulations():
    """With `avoidance.mcts.backup: best` the search ranks by Q first (Decision.by_value):
    the runner-up is the next best Q, not the most simulated, and a tie as printed is
    decided by the Q beyond 3 decimals, never by "more simulations"."""
    from uavxai.avoidance.types import Decision
    from uavxai.xai.explain import runner_up

    chosen, busy, better = _child(0, 10, 0.9), _child(4, 40, 0.5), _child(2, 5, 0.8)
    assert runner_up([chosen, busy, better], chosen).action == 4  # the mean's: most simulated
    assert runner_up([chosen, busy, better], chosen, by_value=True).action == 2
    tied = [_child(0, 10, 0.80001), _child(4, 30, 0.80000)]
    d = Decision(0.0, 1.0, 0, tied, planner="mcts_sep", by_value=True)
    assert "a higher Q beyond 3 decimals decided" in d.explanation
    assert "simulations (10 against 30)" not in d.explanation


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


def test_a_conflict_quotes_its_predicted_miss_not_where_it_first_came_too_close():
    own, intruders = HEAD_ON
    # 3 s of turn cover: the search's line after holding then flies on into the intruder (with
    # the default 4 s it already swerves in the next level, and the miss is that swerve's)
    cfg = PlannerConfig(seed=0, reach_horizon_s=3.0)
    d = MCTSPlanner(cfg).plan(own, intruders, (1000, 1800, 120))
    hold = next(c for c in d.children if c.action == 4)
    m = hold.meets
    # dead ahead: on the predicted tracks the two would nearly touch; where holding first
    # comes inside the separation it needs (75 m here) is no miss distance
    assert m is not None and m.miss_m < 10.0 and m.needed_m >= d.d_min_m
    assert f"meets intruder 7 in {m.time_s:.1f} s (predicted miss {m.miss_m:.0f} m, " in (
        d.explanation
    )


def test_clamped_commands_are_not_called_manoeuvres():
    """At the bank limit and the top speed, "right" and "faster" change nothing: no sentence
    says the aircraft banked right or sped up, and no option that flies the chosen manoeuvre
    is offered as its alternative."""
    import math

    from uavxai.vocabulary import ACTIONS

    own = Ownship(1000, 1000, 120, 30.0, 0.0, bank=math.radians(30))
    for seed in range(4):
        d = MCTSPlanner(PlannerConfig(seed=seed, depth=2)).plan(own, [], (1000, 1900, 120))
        for c in d.children:
            a, flown = ACTIONS[c.action], ACTIONS[c.flies]
            assert flown.accel == min(a.accel, 0) and flown.bank == min(a.bank, 0)
        chosen = next(c for c in d.children if c.action == d.action)
        assert d.explanation.startswith(ACTIONS[chosen.flies].verb)
        assert "banked right" not in d.explanation and "sped up" not in d.explanation
        runner = next(c for c in d.children if d.counterfactual.startswith(f"why not {_phrase(c)}"))
        assert runner.flies != chosen.flies


def _phrase(c) -> str:
    from uavxai.vocabulary import ACTIONS

    return ACTIONS[c.action].phrase + (":" if c.effect is None else " (flies as")


def _meeting_child(action: int, visits: int, q: float, when: float, miss: float):
    from uavxai.avoidance.types import ChildStats, Meeting

    return ChildStats(
        action, 0.0, 0.0, visits, q, miss, 3, when, "collision",
        meets=Meeting(3, when, miss, 75.0),
    )  # fmt: skip


def test_why_not_a_collision_is_said_only_when_the_choice_does_not_collide():
    from uavxai.avoidance.types import Decision

    chosen, runner = _meeting_child(0, 30, 0.05, 9.0, 20.0), _meeting_child(4, 20, 0.04, 6.0, 5.0)
    clear = _child(8, 1, 0.9)
    d = Decision(0.0, 1.0, 0, [chosen, runner, clear], planner="mcts")
    assert "a predicted collision" not in d.counterfactual  # the chosen line collides too
    assert d.counterfactual.startswith("why not holding bank and speed: it meets intruder 3 in ")
    assert " too; " in d.counterfactual


def test_when_every_option_conflicts_the_rule_is_stated_and_applied():
    from uavxai.avoidance.lines import cornered_choice
    from uavxai.avoidance.types import Decision

    kids = [
        _meeting_child(0, 50, 0.03, 6.0, 30.0),  # most simulated, meets soonest
        _meeting_child(4, 10, 0.04, 9.0, 10.0),  # meets latest
        _meeting_child(8, 10, 0.04, 9.0, 25.0),  # as late, passes wider: the rule's pick
    ]
    assert cornered_choice(kids).action == 8
    d = Decision(0.0, 0.0, 8, kids, planner="mcts", cornered=True)
    assert (
        "every option meets an intruder, so it took the one that meets its intruder latest "
        "(in 9.0 s, as another does) and passes it widest (25.0 m against 10.0 m)"
    ) in d.explanation
    assert d.counterfactual.endswith(", as soon and closer")
    assert cornered_choice([*kids, _child(2, 1, 0.9)]) is None  # one option is clear


def test_a_cornered_planner_stays_in_the_area_and_says_so():
    """Every option conflicts, and the one meeting its intruder latest leaves the flight area:
    the rule takes the latest meeting among the lines that stay in (leaving ends the flight
    for certain), and the words say why."""
    from dataclasses import replace

    from uavxai.avoidance.lines import cornered_choice
    from uavxai.avoidance.types import Decision

    inside = _meeting_child(0, 50, 0.03, 6.0, 30.0)
    later_out = replace(_meeting_child(4, 10, 0.04, 9.0, 10.0), outcome="out_of_bounds")
    also_in = _meeting_child(8, 10, 0.04, 5.0, 25.0)
    kids = [inside, later_out, also_in]
    assert cornered_choice(kids).action == 0
    d = Decision(0.0, 0.0, 0, kids, planner="mcts", cornered=True)
    assert ("every option meets an intruder, so it took the one that stays in the flight area "
            "(an option that meets later leaves it) and meets its intruder latest (in 6.0 s, the "
            "next in 5.0 s)") in d.explanation  # fmt: skip
    two = Decision(0.0, 0.0, 0, [inside, later_out], planner="mcts", cornered=True)
    assert two.counterfactual.endswith("75 m needed) and leaves the flight area")
    # with no line leaving, the latest meeting decides as before
    assert cornered_choice([inside, replace(later_out, outcome="collision"), also_in]).action == 4


def test_a_cornered_planner_that_weighs_the_walls_keeps_clear_of_a_trapped_line():
    """mcts_sep (issue 31): a line that ends where it can no longer turn away from a wall
    (``trapped``) counts as leaving, so the rule takes the latest meeting among the others."""
    from dataclasses import replace

    from uavxai.avoidance.lines import cornered_choice, leaves
    from uavxai.avoidance.types import Decision

    inside = _meeting_child(0, 50, 0.03, 6.0, 30.0)
    later_trapped = replace(_meeting_child(4, 10, 0.04, 9.0, 10.0), trapped=True)
    assert leaves(later_trapped) and not leaves(inside)
    assert cornered_choice([inside, later_trapped]).action == 0
    assert cornered_choice([inside, replace(later_trapped, trapped=False)]).action == 4
    d = Decision(0.0, 0.0, 0, [inside, later_trapped], planner="mcts_sep", cornered=True)
    assert ("so it took the one that stays in the flight area (an option that meets later can "
            "no longer stay in it)") in d.explanation  # fmt: skip
    assert d.counterfactual.endswith("and can no longer turn away from the area's edge")


def test_a_route_line_that_leaves_the_area_is_not_kept():
    from dataclasses import replace

    from uavxai.avoidance.mcts import _final_action

    clear = replace(_child(4, 10, 0.5), outcome="")
    leaving = replace(clear, outcome="out_of_bounds")
    assert _final_action([_child(0, 30, 0.6), clear], 0, 4) == (4, False, True)
    assert _final_action([_child(0, 30, 0.6), leaving], 0, 4) == (0, False, False)


def test_steering_away_needs_holding_to_conflict():
    hold_clear = [_child(4, 30, 0.8), _meeting_child(0, 10, 0.05, 6.0, 5.0), _child(8, 40, 0.9)]
    assert not is_avoidance(hold_clear, 8, 50.0)  # another option conflicted, holding did not
    hold_meets = [_meeting_child(4, 30, 0.05, 6.0, 5.0), _child(8, 40, 0.9)]
    assert is_avoidance(hold_meets, 8, 50.0)


def test_a_fleet_member_is_named_as_one_not_as_an_intruder():
    from uavxai.xai.explain import _name

    # a member's picture holds the other members as "ownship-j" (docs/fleet.md)
    assert _name("ownship-0") == "fleet member 0"
    assert _name("intruder-7") == "intruder 7"
    assert _name(3) == "intruder 3"


def test_explain_counts_the_members_by_the_runs_summary_not_by_files_left_in_the_folder(
    tmp_path,
):
    """A decisions-j.jsonl another run left in the folder is not read as this run's member:
    the members are those of summary.json's ``fleet``; without a summary, the files count."""
    import json

    import pytest

    from uavxai.errors import UserError
    from uavxai.xai.explain import read_decisions

    record = json.dumps({"t": 1.0, "action": 4, "children": [], "explanation": "hold"})
    for name in ("decisions.jsonl", "decisions-1.jsonl", "decisions-2.jsonl"):
        (tmp_path / name).write_text(record + "\n")
    assert len(read_decisions(tmp_path, 2)) == 1  # no summary: three files, three members
    (tmp_path / "summary.json").write_text(json.dumps({"fleet": [{"id": 0}, {"id": 1}]}))
    assert len(read_decisions(tmp_path, 1)) == 1
    with pytest.raises(UserError, match="has no member 2; it flew members 0 to 1"):
        read_decisions(tmp_path, 2)
    (tmp_path / "summary.json").write_text(json.dumps({"outcome": "goal"}))  # one ownship
    with pytest.raises(UserError, match="has no member 1; it flew one UAV, member 0"):
        read_decisions(tmp_path, 1)
    assert len(read_decisions(tmp_path, 0)) == 1


def test_a_record_holds_every_intruder_field_the_planner_read() -> None:
    """decisions.jsonl's believed intruders rebuild the planner's inputs exactly (the audit
    re-plans from them with Intruder(**record)): every field of Intruder is written, the
    vertical errors and a fleet member's clearance included."""
    import dataclasses

    seen = Intruder(id="ownship-2", x=900.0, y=1000.0, h=130.0, vx=-15.0, vy=2.0, vh=0.5,
                    turn_rate=0.05, sigma_m=4.0, sigma_v=2.5, age_s=0.4, keep_m=30.0,
                    bank_limit_deg=45.0, sigma_h_m=3.0, sigma_vh=0.7)  # fmt: skip
    assert all(getattr(seen, f.name) != f.default for f in dataclasses.fields(Intruder)
               if f.name != "id")  # fmt: skip  (every field set off its default)
    own = Ownship(500.0, 1000.0, 120.0, 20.0, 1.5708)
    decision = MCTSPlanner(PlannerConfig(seed=0)).plan(own, [seen], (1500.0, 1000.0, 120.0))
    record = json.loads(json.dumps(decision_record(0.0, own, [seen], decision)))
    assert [Intruder(**i) for i in record["state"]["intruders"]] == [seen]


def _passing_child(action: int, q: float, when: float, miss: float, closest: float, **kw):
    """A conflicting option meeting intruder 3 in ``when`` s at ``miss`` m that comes
    ``closest`` m from the nearest intruder (another one) on its line."""
    from dataclasses import replace

    return replace(_meeting_child(action, 10, q, when, miss), predicted_min_separation_m=closest,
                   **kw)  # fmt: skip


def test_the_widest_cornered_rule_keeps_the_miss_not_the_latest_meeting():
    """`avoidance.mcts.cornered_rule: widest` (issue 31, a32): every option conflicts; the one
    passing the nearest intruder widest wins, whatever the intruder it meets first, and the
    latest meeting decides only between lines passing 2 d_min or more (the a31 graze: the latest
    meeting's rule took a line meeting intruder 39 at 78.8 m that passed intruder 35 at 28.6 m)."""
    from dataclasses import replace

    from uavxai.avoidance.lines import cornered_choice
    from uavxai.avoidance.types import Decision

    graze = _passing_child(0, 0.006, 2.0, 78.8, 28.6)  # the latest rule's pick: meets widest
    wide = _passing_child(8, 0.006, 2.0, 49.7, 49.7)
    kids = [graze, _passing_child(4, 0.006, 2.0, 43.9, 43.9), wide]
    assert cornered_choice(kids).action == 0  # "latest": the met intruder's miss, 78.8 m
    assert cornered_choice(kids, rule="widest", d_min_m=50.0).action == 8
    d = Decision(0.0, 0.0, 8, kids, planner="mcts_sep", cornered=True, cornered_rule="widest")
    assert ("every option meets an intruder, so it took the one that passes the traffic widest "
            "(49.7 m from the nearest intruder against 43.9 m)") in d.explanation  # fmt: skip
    assert d.counterfactual.endswith(
        ", and comes nearer the traffic (43.9 m from the nearest intruder against 49.7 m)"
    )
    assert d.to_json()["cornered_rule"] == "widest"
    assert "cornered_rule" not in replace(d, cornered_rule="latest").to_json()
    # past twice d_min every line is as good: the latest meeting decides, and the words say so
    far = _passing_child(0, 0.01, 2.0, 90.0, 180.0)
    later = _passing_child(4, 0.01, 5.0, 90.0, 120.0)
    assert cornered_choice([far, later], rule="widest", d_min_m=50.0).action == 4
    d = Decision(0.0, 0.0, 4, [far, later], planner="mcts_sep", cornered=True,
                 cornered_rule="widest")  # fmt: skip
    assert ("passes the traffic as wide as another (100 m or more) and meets its intruder latest "
            "(in 5.0 s, the next in 2.0 s)") in d.explanation  # fmt: skip
    assert d.counterfactual.endswith(", sooner")
    # as late too: the wider pass decides
    same = _passing_child(0, 0.01, 5.0, 90.0, 180.0)
    d = Decision(0.0, 0.0, 0, [same, later], planner="mcts_sep", cornered=True,
                 cornered_rule="widest")  # fmt: skip
    assert cornered_choice([same, later], rule="widest", d_min_m=50.0).action == 0
    assert "meets its intruder as late, passing wider (180.0 m against 120.0 m)" in d.explanation
    assert d.counterfactual.endswith(", as soon and nearer the traffic")


def test_the_widest_cornered_rule_still_keeps_in_the_area_first():
    from dataclasses import replace

    from uavxai.avoidance.lines import cornered_choice
    from uavxai.avoidance.types import Decision

    inside = _passing_child(0, 0.01, 2.0, 60.0, 30.0)
    out = replace(_passing_child(4, 0.01, 2.0, 60.0, 45.0), outcome="out_of_bounds")
    trapped = replace(_passing_child(8, 0.01, 2.0, 60.0, 48.0), trapped=True)
    kids = [inside, out, trapped]
    assert cornered_choice(kids, rule="widest", d_min_m=50.0).action == 0
    d = Decision(0.0, 0.0, 0, kids, planner="mcts_sep", cornered=True, cornered_rule="widest")
    assert ("so it took the one that stays in the flight area (an option that passes wider or "
            "meets later leaves it) and passes the traffic at 30.0 m from the nearest "
            "intruder") in d.explanation  # fmt: skip
    assert d.counterfactual.endswith("and can no longer turn away from the area's edge")


def test_the_widest_rule_needs_the_collision_distance():
    from uavxai.avoidance.lines import cornered_choice

    kids = [_passing_child(0, 0.01, 2.0, 60.0, 30.0), _passing_child(4, 0.01, 2.0, 60.0, 45.0)]
    with pytest.raises(ValueError, match="collision distance"):
        cornered_choice(kids, rule="widest")


def test_only_the_mcts_planners_take_the_cornered_rule():
    """exhaustive (the reference) and mcts_daa (its judged figures) keep "latest"."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig

    cfg = PlannerConfig(cornered_rule="widest")
    assert make_planner("mcts_sep", cfg).config.cornered_rule == "widest"
    assert make_planner("exhaustive", cfg).config.cornered_rule == "latest"
    assert make_planner("mcts_daa", cfg).inner.config.cornered_rule == "latest"


def test_the_widest_rule_words_for_a_tie_below_the_cap_and_a_full_tie():
    """The two remaining word forms of the widest rule: widths equal below 2 d_min (the latest
    meeting decides), and equal in everything the rule weighs (the search decides, and says so).
    Widths that differ by under 0.1 m are printed to the centimetre."""
    from uavxai.avoidance.types import Decision

    a, b = _passing_child(0, 0.01001, 5.0, 60.0, 70.0), _passing_child(4, 0.01, 2.0, 60.0, 70.0)
    d = Decision(0.0, 0.0, 0, [a, b], planner="mcts", cornered=True, cornered_rule="widest")
    assert ("passes the traffic as wide as another (70.0 m) and meets its intruder latest "
            "(in 5.0 s, the next in 2.0 s)") in d.explanation  # fmt: skip
    c = _passing_child(4, 0.01, 5.0, 60.0, 70.0)
    d = Decision(0.0, 0.0, 0, [a, c], planner="mcts", cornered=True, cornered_rule="widest")
    why = "as many simulations (10 each): a higher Q beyond 3 decimals"
    assert f"meets its intruder as late, tied: {why}" in d.explanation
    assert d.counterfactual.endswith(f", the same; {why}")
    near, far = _passing_child(0, 0.01, 2.0, 60.0, 49.74), _passing_child(4, 0.01, 2.0, 60.0, 49.71)
    d = Decision(0.0, 0.0, 0, [near, far], planner="mcts", cornered=True, cornered_rule="widest")
    assert "(49.74 m from the nearest intruder against 49.71 m)" in d.explanation


def test_a_cornered_rule_outside_the_list_is_refused_at_load(tmp_path, capsys):
    from uavxai.cli import main

    path = tmp_path / "s.yaml"
    path.write_text("name: x\navoidance:\n  mcts:\n    cornered_rule: nearest\n")
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "cornered_rule" in err and "widest" in err
