"""`uavxai evaluate`: files and columns, seeded rows, local workers and Ray give the same rows,
the JSBSim episode loop, and (slow) the paper's claim on a reduced campaign."""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
import sys
from pathlib import Path

import numpy as np
import pytest

from uavxai.campaign import (
    DAA_COLUMNS,
    DAA_EPISODE_COLUMNS,
    EPISODE_COLUMNS,
    FLIGHT_COLUMNS,
    FLIGHT_RESULTS,
    RESULT_COLUMNS,
    TIMING_COLUMNS,
    evaluate_command,
    merge_campaigns,
    rerun_row,
    run_campaign,
    run_campaign_episode,
    summarise,
)
from uavxai.cli import MARKER, main
from uavxai.errors import UserError
from uavxai.geometry import closest_approach
from uavxai.scenario import default_scenario

SCENARIO = default_scenario("campaign-test")
METHODS = ["none", "dqn"]
COUNTS = [5, 20]


def _read(path: Path) -> tuple[list[str], list[dict]]:
    with path.open() as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


def _seeded(rows: list[dict]) -> list[dict]:
    """The columns that depend only on the seed (not on the machine's speed)."""
    return [
        {k: v for k, v in r.items() if k not in TIMING_COLUMNS and k != "decision_ms"} for r in rows
    ]


@pytest.fixture(scope="module")
def local_rows() -> list[dict]:
    return run_campaign(SCENARIO, METHODS, COUNTS, 3, workers=1)


def test_evaluate_writes_results_episodes_and_plots(tmp_path: Path) -> None:
    report = evaluate_command(
        SCENARIO,
        methods=METHODS,
        intruders=COUNTS,
        episodes=3,
        dynamics="kinematic",
        workers=1,
        ray_address=None,
        out=tmp_path,
    )
    assert report["episodes"] == 12
    columns, results = _read(tmp_path / "results.csv")
    assert columns == list(RESULT_COLUMNS + FLIGHT_RESULTS + DAA_COLUMNS)
    assert columns[:9] == [
        "method",
        "intruders",
        "episodes",
        "goal_rate",
        "collision_rate",
        "timeout_rate",
        "mean_steps",
        "mean_min_separation_m",
        "decision_ms_p50",
    ]  # README "What a run produces", in order
    assert [(r["method"], int(r["intruders"])) for r in results] == [
        (m, n) for m in METHODS for n in COUNTS
    ]
    for r in results:
        assert int(r["episodes"]) == 3
        outcome_rates = ("goal", "collision", "timeout", "out_of_bounds", "fdm_failure")
        rates = [float(r[f"{k}_rate"]) for k in outcome_rates]
        assert all(0.0 <= x <= 1.0 for x in rates)
        assert sum(rates) == pytest.approx(1.0, abs=1e-5)  # each rate is rounded to 6 digits
        for k in ("collision_rate", "nmac_rate"):  # Wilson intervals hold the rate
            assert float(r[f"{k}_lo"]) <= float(r[k]) <= float(r[f"{k}_hi"])
        assert float(r["mean_steps"]) >= 1 and float(r["decision_ms_p50"]) > 0
    columns, episodes = _read(tmp_path / "episodes.csv")
    assert columns == list(EPISODE_COLUMNS + FLIGHT_COLUMNS + DAA_EPISODE_COLUMNS)
    assert len(episodes) == 12
    for e in episodes:  # random traffic: every seed weighs 1; an NMAC is inside well clear
        assert float(e["weight"]) == 1.0 and int(e["lowc"]) >= int(e["nmac"])
        if e["method"] == "none":
            assert int(e["alert"]) == int(e["manoeuvre"]) == 0
    assert {e["outcome"] for e in episodes} <= {"goal", "collision", "timeout", "out_of_bounds"}
    assert [int(e["seed"]) for e in episodes[:3]] == [SCENARIO.seed + i for i in range(3)]
    for name in ("goal_rate.png", "collision_rate.png", "steps.png"):
        assert (tmp_path / name).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_results_agree_with_the_episode_rows(local_rows: list[dict]) -> None:
    for r in summarise(local_rows):
        mine = [
            e for e in local_rows if (e["method"], e["intruders"]) == (r["method"], r["intruders"])
        ]
        assert r["goal_rate"] == sum(e["outcome"] == "goal" for e in mine) / len(mine)
        assert r["collision_rate"] == sum(e["outcome"] == "collision" for e in mine) / len(mine)
        assert r["mean_steps"] == pytest.approx(np.mean([e["steps"] for e in mine]))


def test_same_seed_same_rows_and_any_row_reruns_alone(local_rows: list[dict]) -> None:
    again = run_campaign(SCENARIO, METHODS, COUNTS, 3, workers=1)
    assert _seeded(again) == _seeded(local_rows)
    # Every method meets the same encounters: episode i has seed scenario.seed + i.
    assert {(r["episode"], r["seed"]) for r in local_rows} == {(i, i) for i in range(3)}
    row = local_rows[-1]
    alone = run_campaign_episode(SCENARIO, row["method"], row["intruders"], row["seed"])
    assert _seeded([{**alone, "episode": row["episode"]}]) == _seeded([row])
    other_seed = run_campaign(SCENARIO.with_seed(100), ["none"], [20], 3, workers=1)
    assert [r["seed"] for r in other_seed] == [100, 101, 102]


def test_rerun_row_from_the_scenario_file(tmp_path: Path, local_rows: list[dict]) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("name: campaign-test\n")
    row = next(r for r in local_rows if r["method"] == "none" and r["intruders"] == 20)
    again = rerun_row(path, "none", 20, row["seed"])
    assert again["outcome"] == row["outcome"] and again["steps"] == row["steps"]
    assert again["min_separation_m"] == row["min_separation_m"]


def test_two_workers_give_the_same_rows(local_rows: list[dict]) -> None:
    pooled = run_campaign(SCENARIO, METHODS, COUNTS, 3, workers=2)
    assert _seeded(pooled) == _seeded(local_rows)


def test_bad_requests_are_user_errors() -> None:
    with pytest.raises(UserError, match="astar"):
        run_campaign(SCENARIO, ["astar"], [5], 1)
    with pytest.raises(UserError, match="--intruders"):
        run_campaign(SCENARIO, ["none"], [], 1)
    with pytest.raises(UserError, match="--dynamics"):
        run_campaign(SCENARIO, ["none"], [5], 1, dynamics="xplane")
    fixed = default_scenario(
        "fixed",
        intruders={"list": [{"x": 900, "y": 900, "h": 120, "heading_deg": 0, "speed_mps": 20}]},
    )
    with pytest.raises(UserError, match="intruders.list"):
        run_campaign(fixed, ["none"], [5], 1)


def test_evaluate_through_the_cli(tmp_path: Path) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: cli-campaign\nseed: 5\n")
    out = tmp_path / "out"
    args = ["evaluate", str(scenario), "--methods", "none", "--intruders", "3", "--episodes", "2"]
    assert main([*args, "--out", str(out)]) == 0
    _, rows = _read(out / "episodes.csv")
    assert [int(r["seed"]) for r in rows] == [5, 6]
    assert main([*args, "--out", str(out)]) == 2  # never overwrites without --force


def test_merge_campaigns_of_different_methods(tmp_path: Path) -> None:
    kwargs = dict(intruders=[40], episodes=2, dynamics="kinematic", workers=1, ray_address=None)
    evaluate_command(SCENARIO, methods=["none"], out=tmp_path / "a", **kwargs)
    evaluate_command(SCENARIO, methods=["mcts_fast"], out=tmp_path / "b", **kwargs)
    merged = merge_campaigns([tmp_path / "a", tmp_path / "b"], tmp_path / "ab")
    assert [r["method"] for r in merged] == ["none", "mcts_fast"]
    columns, rows = _read(tmp_path / "ab" / "results.csv")
    assert columns == list(RESULT_COLUMNS + FLIGHT_RESULTS + DAA_COLUMNS) and len(rows) == 2
    _, a_rows = _read(tmp_path / "a" / "results.csv")
    assert rows[0] == a_rows[0]
    # flown apart, mcts_fast had no `none` to compare with; merged, it has (seed 1 is an NMAC
    # for `none`)
    _, b_rows = _read(tmp_path / "b" / "results.csv")
    assert b_rows[0]["risk_ratio"] == "" and rows[1]["risk_ratio"] != ""
    # weight 1 each, the weighted NMAC risk ratio is the plain one
    assert b_rows[0]["nmac_risk_ratio"] == ""
    assert rows[1]["nmac_risk_ratio"] == rows[1]["risk_ratio"]
    assert rows[1]["decision_ms_p50"] == b_rows[0]["decision_ms_p50"]
    _, episodes = _read(tmp_path / "ab" / "episodes.csv")
    assert len(episodes) == 4
    assert (tmp_path / "ab" / "collision_rate.png").is_file()
    with pytest.raises(UserError, match="seed 0: flown in both"):
        merge_campaigns([tmp_path / "a", tmp_path / "a"], tmp_path / "aa")
    # a campaign written before the flight-quality columns merges with them empty
    old = tmp_path / "a" / "episodes.csv"
    head, *body = (ln.split(",") for ln in old.read_text().splitlines())
    keep = [i for i, c in enumerate(head) if c not in FLIGHT_COLUMNS]
    old.write_text("".join(",".join(r[i] for i in keep) + "\n" for r in [head, *body]))
    merge_campaigns([tmp_path / "a", tmp_path / "b"], tmp_path / "old")
    _, merged_rows = _read(tmp_path / "old" / "episodes.csv")
    assert [r["path_excess"] == "" for r in merged_rows] == [True, True, False, False]
    # one written before random traffic carried the detect-and-avoid record is refused
    head, *body = (ln.split(",") for ln in old.read_text().splitlines())
    keep = [i for i, c in enumerate(head) if c not in DAA_EPISODE_COLUMNS]
    old.write_text("".join(",".join(r[i] for i in keep) + "\n" for r in [head, *body]))
    with pytest.raises(UserError, match="without it"):
        merge_campaigns([tmp_path / "a", tmp_path / "b"], tmp_path / "older")


def test_merge_pools_seeds_into_the_campaign_flown_at_once(tmp_path: Path) -> None:
    """Seeds 0-1 and 2-4 flown apart, then merged, give the rows of seeds 0-4 flown at once:
    rates, intervals and the paired risk ratio alike."""
    kwargs = dict(methods=["none", "mvp"], intruders=[40], dynamics="kinematic",
                  workers=1, ray_address=None)  # fmt: skip
    own = SCENARIO.ownship.model_copy(update={"goal": (900.0, 950.0, 120.0)})
    goal = SCENARIO.model_copy(update={"ownship": own})
    evaluate_command(goal, episodes=2, out=tmp_path / "first", **kwargs)
    evaluate_command(goal.with_seed(2), episodes=3, out=tmp_path / "more", **kwargs)
    evaluate_command(goal, episodes=5, out=tmp_path / "once", **kwargs)
    merge_campaigns([tmp_path / "first", tmp_path / "more"], tmp_path / "pooled")
    _, pooled = _read(tmp_path / "pooled" / "results.csv")
    _, once = _read(tmp_path / "once" / "results.csv")
    assert _seeded(pooled) == _seeded(once)
    assert [r["episodes"] for r in pooled] == ["5", "5"]
    assert pooled[1]["risk_ratio"] != ""  # `none` had NMACs to compare with
    _, episodes = _read(tmp_path / "pooled" / "episodes.csv")
    assert sorted({int(r["seed"]) for r in episodes}) == [0, 1, 2, 3, 4]
    assert {(r["goal_x"], r["goal_y"], r["goal_h"]) for r in episodes} == {("900", "950", "120")}


def test_merge_refuses_campaigns_that_flew_to_other_goals(tmp_path: Path) -> None:
    """Without ownship.goal a campaign flies to the service point of its seed: another --seed
    is another goal, and its seeds are not the same encounters."""
    kwargs = dict(methods=["none"], intruders=[3], episodes=1, dynamics="kinematic",
                  workers=1, ray_address=None)  # fmt: skip
    evaluate_command(SCENARIO, out=tmp_path / "a", **kwargs)
    evaluate_command(SCENARIO.with_seed(1), out=tmp_path / "b", **kwargs)
    _, a = _read(tmp_path / "a" / "episodes.csv")
    _, b = _read(tmp_path / "b" / "episodes.csv")
    assert (a[0]["goal_x"], a[0]["goal_y"]) != (b[0]["goal_x"], b[0]["goal_y"])
    with pytest.raises(UserError, match="flew to different goals"):
        merge_campaigns([tmp_path / "a", tmp_path / "b"], tmp_path / "ab")
    # the row's goal flies it again as it was flown
    (tmp_path / "s.yaml").write_text("name: campaign-test\n")  # SCENARIO, seed 0
    again = rerun_row(tmp_path / "s.yaml", "none", 3, 1,
                      goal=[float(b[0][k]) for k in ("goal_x", "goal_y", "goal_h")])  # fmt: skip
    assert again["min_separation_m"] == pytest.approx(float(b[0]["min_separation_m"]), abs=1e-3)


def test_merge_refuses_what_is_not_a_campaign(tmp_path: Path) -> None:
    kwargs = dict(intruders=[3], episodes=1, dynamics="kinematic", workers=1, ray_address=None)
    evaluate_command(SCENARIO, methods=["none"], out=tmp_path / "a", **kwargs)
    with pytest.raises(UserError, match="no such file; is .* a campaign folder"):
        merge_campaigns([tmp_path / "a", tmp_path / "nothing"], tmp_path / "m")
    (tmp_path / "b").mkdir()
    (tmp_path / "b" / "episodes.csv").write_text("method,seed\nnone,1\n")
    with pytest.raises(UserError, match="lacks the columns intruders, episode, outcome"):
        merge_campaigns([tmp_path / "b"], tmp_path / "m")
    (tmp_path / "a" / "episodes.csv").write_text(
        (tmp_path / "a" / "episodes.csv").read_text().replace("none,3,0,0,", "none,3,0,seven,")
    )
    with pytest.raises(UserError, match="line 2: seed .seven. is not allowed; seed must be a"):
        merge_campaigns([tmp_path / "a"], tmp_path / "m")


def test_merge_through_the_cli(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: cli-merge\nownship:\n  goal: [900, 900, 120]\n")
    for name, seed in (("one", "1"), ("two", "3")):
        args = ["evaluate", str(scenario), "--methods", "none", "--intruders", "3", "--episodes",
                "2", "--seed", seed, "--out", str(tmp_path / name)]  # fmt: skip
        assert main(args) == 0
    out = tmp_path / "both"
    assert main(["merge", str(tmp_path / "one"), str(tmp_path / "two"), "--out", str(out)]) == 0
    _, rows = _read(out / "results.csv")
    assert [(r["method"], r["episodes"]) for r in rows] == [("none", "4")]
    assert "none" in capsys.readouterr().out
    # never into one of its sources, never over a folder without --force
    assert main(["merge", str(tmp_path / "one"), "--out", str(tmp_path / "one"), "--force"]) == 2
    assert (tmp_path / "one" / "episodes.csv").is_file()
    assert main(["merge", str(tmp_path / "one"), "--out", str(out)]) == 2
    # --force never empties a folder that holds a source (it was gone before it was read),
    # and a merge that refuses its sources leaves the previous output as it was
    inner = out / "inner"
    shutil.copytree(tmp_path / "one", inner)
    assert main(["merge", str(inner), "--out", str(out), "--force"]) == 2
    assert "holds the source" in capsys.readouterr().err
    assert (inner / "episodes.csv").is_file() and (out / "results.csv").is_file()
    shutil.rmtree(inner)
    broken = tmp_path / "broken"
    shutil.copytree(tmp_path / "one", broken)
    (broken / "episodes.csv").write_text("method\n")
    before = {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()}
    assert main(["merge", str(broken), "--out", str(out), "--force"]) == 2
    assert "lacks the columns" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in out.iterdir() if p.is_file()} == before
    # a campaign of other dynamics is not the same encounters
    other = tmp_path / "jsb"
    other.mkdir()
    for f in ("results.csv", "episodes.csv"):
        (other / f).write_text((tmp_path / "one" / f).read_text())
    marker = json.loads((tmp_path / "one" / MARKER).read_text())
    marker["argv"] += ["--dynamics", "jsbsim"]
    (other / MARKER).write_text(json.dumps(marker))
    capsys.readouterr()
    assert main(["merge", str(tmp_path / "one"), str(other), "--out", str(tmp_path / "x")]) == 2
    assert "different scenarios or dynamics" in capsys.readouterr().err


def test_closest_approach_catches_a_pass_through_between_samples() -> None:
    # Ownship east 0 -> 40 m; intruder north through its path: at the samples they are 28 m
    # and more apart... and they pass 0 m apart halfway.
    p0, p1 = np.array([0.0, 0.0, 100.0]), np.array([40.0, 0.0, 100.0])
    q0, q1 = np.array([[20.0, -20.0, 100.0]]), np.array([[20.0, 20.0, 100.0]])
    assert min(np.linalg.norm(q0 - p0), np.linalg.norm(q1 - p1)) > 28.0
    assert closest_approach(p0, p1, q0, q1) == pytest.approx(0.0, abs=1e-9)
    assert closest_approach(p0, p1, np.zeros((0, 3)), np.zeros((0, 3))) == math.inf


def test_jsbsim_episode_flies_the_same_encounter() -> None:
    sc = default_scenario("jsbsim-campaign", avoidance={"max_steps": 12})
    row = run_campaign_episode(sc, "none", 5, 3, dynamics="jsbsim")
    assert row["outcome"] in ("goal", "collision", "timeout", "out_of_bounds")
    assert row["steps"] == 12 and row["outcome"] == "timeout"
    assert row["flight_time_s"] == pytest.approx(12.0, abs=0.05)
    kin = run_campaign_episode(sc, "none", 5, 3, dynamics="kinematic")
    assert kin["steps"] == 12
    # Same traffic, same planner, 12 s: the flown minimum separations agree to within metres.
    assert row["min_separation_m"] == pytest.approx(kin["min_separation_m"], rel=0.1)


def test_missing_ray_says_how_to_install_it(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setitem(sys.modules, "ray", None)  # what `import ray` sees without Ray
    with pytest.raises(UserError, match=r"pip install 'uavxai\[ray\]'"):
        run_campaign(SCENARIO, ["none"], [3], 1, ray_address="local")


@pytest.mark.slow
def test_ray_local_gives_the_same_rows(local_rows: list[dict]) -> None:
    ray = pytest.importorskip("ray")
    os.environ["RAY_USAGE_STATS_ENABLED"] = "0"
    ray.init(num_cpus=2, include_dashboard=False)
    try:
        rows = run_campaign(SCENARIO, METHODS, COUNTS, 3, ray_address="auto")
    finally:
        ray.shutdown()
    assert _seeded(rows) == _seeded(local_rows)


@pytest.mark.slow
def test_mcts_beats_the_learned_baselines_on_collisions() -> None:
    """The paper's claim on a reduced campaign: 40 episodes at 20 and 40 intruders. MCTS
    collides no more often than either learned planner at each density, and less often
    over the campaign. (Not "less often at each density": at 20 straight intruders none of
    the three collides in 40 episodes, where no planner can be shown better than another.)"""
    rows = run_campaign(SCENARIO, ["mcts", "dqn", "safe_dqn"], [20, 40], 40, workers=2)
    rate = {(r["method"], r["intruders"]): r["collision_rate"] for r in summarise(rows)}
    for baseline in ("dqn", "safe_dqn"):
        for n in (20, 40):
            assert rate[("mcts", n)] <= rate[(baseline, n)], (n, rate)
        assert sum(rate[("mcts", n)] for n in (20, 40)) < sum(
            rate[(baseline, n)] for n in (20, 40)
        ), rate


def test_a_campaign_extended_with_another_seed_merges_without_ownship_goal(
    tmp_path: Path,
) -> None:
    """`uavxai evaluate --seed N` flies other encounters to the same goal, the service point of
    the scenario file's own seed, so that a campaign extended later merges (issue 30)."""
    scenario = tmp_path / "s.yaml"
    scenario.write_text("name: extend\nseed: 5\nservice: {planner: random, steps: 5}\n")
    runs = {"first": [], "later": ["--seed", "7"]}
    for name, seed in runs.items():
        args = ["evaluate", str(scenario), "--methods", "none", "--intruders", "3", "--episodes",
                "2", *seed, "--out", str(tmp_path / name)]  # fmt: skip
        assert main(args) == 0
    _, first = _read(tmp_path / "first" / "episodes.csv")
    _, later = _read(tmp_path / "later" / "episodes.csv")
    goal = ("goal_x", "goal_y", "goal_h")
    assert [first[0][k] for k in goal] == [later[0][k] for k in goal]
    assert sorted(int(r["seed"]) for r in first + later) == [5, 6, 7, 8]
    out = tmp_path / "both"
    assert main(["merge", str(tmp_path / "first"), str(tmp_path / "later"), "--out", str(out)]) == 0
    _, rows = _read(out / "results.csv")
    assert [(r["method"], r["episodes"]) for r in rows] == [("none", "4")]

