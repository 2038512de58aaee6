"""Learned avoidance baselines: observation, shipped checkpoints, decisions, checkpoint errors,
and a training smoke run that must change the networks and lower the TD loss."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
import torch

from uavxai.avoidance import learned
from uavxai.avoidance.learned import (
    DQNPlanner,
    QNetwork,
    SafeDQNPlanner,
    load_checkpoint,
    obs_dim,
    safe_action,
    save_checkpoint,
)
from uavxai.avoidance.mcts import intruder_arrays
from uavxai.avoidance.model import ownship_state
from uavxai.avoidance.observation import SCALE_M, TCPA_SCALE_S, observe
from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import N_ACTIONS, Decision, Intruder, Ownship, PlannerConfig
from uavxai.cli import main
from uavxai.errors import CheckpointError
from uavxai.scenario import default_scenario

CONFIG = PlannerConfig()


@pytest.fixture(autouse=True)
def _one_torch_thread():
    """One thread, as in training and campaigns: a second one only contends on small nets."""
    threads = torch.get_num_threads()
    torch.set_num_threads(1)
    yield
    torch.set_num_threads(threads)


OWN = Ownship(x=500.0, y=500.0, h=120.0, speed=20.0, heading=math.radians(45.0))
GOAL = (1000.0, 1000.0, 100.0)


def _traffic(n: int, seed: int = 0) -> list[Intruder]:
    rng = np.random.default_rng(seed)
    return [
        Intruder(
            i + 1, *rng.uniform(0.0, 2000.0, 2), rng.uniform(100, 140), *rng.uniform(-20, 20, 2)
        )
        for i in range(n)
    ]


# ------------------------------------------------------------------------------ observation
def test_observation_size_does_not_depend_on_the_intruder_count() -> None:
    state = learned.ownship_state(OWN)
    sizes = set()
    for n in (0, 1, 5, 40):
        intruders = _traffic(n)
        pos = np.array([[i.x, i.y, i.h] for i in intruders]).reshape(n, 3)
        vel = np.array([[i.vx, i.vy, i.vh] for i in intruders]).reshape(n, 3)
        obs = observe(state, pos, vel, np.array(GOAL), CONFIG)
        assert obs.dtype == np.float32 and np.all(np.isfinite(obs))
        sizes.add(obs.shape)
    assert sizes == {(obs_dim(),)}


def test_closest_approach_features_of_a_head_on_intruder() -> None:
    # Ownship north at 20 m/s; an intruder 600 m ahead flying south at 10 m/s, 30 m to the
    # right: it passes 30 m away in 600 / 30 = 20 s.
    own = Ownship(x=1000.0, y=1000.0, h=120.0, speed=20.0, heading=0.0)
    state = learned.ownship_state(own)
    pos, vel = np.array([[1030.0, 1600.0, 120.0]]), np.array([[0.0, -10.0, 0.0]])
    obs = observe(state, pos, vel, np.array(GOAL), CONFIG, n_nearest=2)
    dcpa, tcpa = obs[-4], obs[-3]
    assert dcpa * SCALE_M == pytest.approx(30.0, abs=1e-3)
    assert tcpa * TCPA_SCALE_S == pytest.approx(20.0, abs=1e-3)
    assert np.all(obs[-2:] == 0.0)  # the absent second slot


def test_safe_action_keeps_to_the_safer_half() -> None:
    q_goal = torch.tensor([[20.0, 4.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0]])
    q_safety = torch.tensor([[-9.0, -0.1, 0.0, 0.1, 0.2, -5.0, -6.0, -7.0, -8.0]])
    # Action 0 has the best goal Q and the best sum, but it is the least safe: excluded.
    assert int(safe_action(q_goal, q_safety)) == 1
    assert int((q_goal + q_safety).argmax()) == 0


# ------------------------------------------------------------------------ shipped planners
@pytest.mark.parametrize("name", ["dqn", "safe_dqn"])
def test_shipped_planners_return_valid_decisions(name: str) -> None:
    planner = make_planner(name, CONFIG)
    assert planner.name == name
    for n in (0, 3, 40):
        d = planner.plan(OWN, _traffic(n, seed=n), GOAL)
        assert isinstance(d, Decision)
        assert 0 <= d.action < N_ACTIONS
        assert abs(d.bank_cmd_rad) <= CONFIG.bank_limit_rad + 1e-9
        assert d.accel_mps2 in (-CONFIG.accel_mps2, 0.0, CONFIG.accel_mps2)
        assert [c.action for c in d.children] == list(range(N_ACTIONS))
        assert all(c.visits == 0 and math.isfinite(c.q) for c in d.children)
        assert d.explanation.startswith("DQN:" if name == "dqn" else "Safe-DQN:")
        assert d.counterfactual.startswith("why not")
        assert d.planner == name and d.ms > 0
        if n == 0:
            assert all(c.closest_intruder is None for c in d.children)
        else:
            seps = [c.predicted_min_separation_m for c in d.children]
            assert all(math.isfinite(s) and s >= 0 for s in seps)
        d.to_json()  # serialisable as a decisions.jsonl line


def test_dqn_chooses_its_highest_q_and_safe_dqn_its_filtered_best() -> None:
    intruders = _traffic(20, seed=7)
    d = DQNPlanner(CONFIG).plan(OWN, intruders, GOAL)
    qs = [c.q for c in d.children]
    assert d.action == int(np.argmax(qs))

    safe = SafeDQNPlanner(CONFIG)
    d = safe.plan(OWN, intruders, GOAL)
    pos, vel = intruder_arrays(intruders)
    goal = np.asarray(GOAL, float)
    obs = observe(ownship_state(OWN), pos, vel, goal, CONFIG, safe.n_nearest)
    q = safe.q_values(obs)
    passed = q["safety"] >= np.sort(q["safety"])[4]
    assert passed[d.action]
    total = np.where(passed, q["goal"] + q["safety"], -np.inf)
    assert d.action == int(np.argmax(total))
    assert d.children[d.action].q == pytest.approx(total[d.action])


def test_same_inputs_same_decision() -> None:
    intruders = _traffic(10, seed=3)
    a = SafeDQNPlanner(CONFIG).plan(OWN, intruders, GOAL)
    b = SafeDQNPlanner(CONFIG).plan(OWN, intruders, GOAL)
    assert a.action == b.action and [c.q for c in a.children] == [c.q for c in b.children]


def test_shipped_checkpoints_are_small_and_documented() -> None:
    for algo in learned.ALGOS:
        path = learned.shipped_checkpoint(algo)
        assert path.stat().st_size < 1_000_000
        info = path.with_suffix(".json").read_text()
        assert '"trained_on"' in info and algo in info


HEAD_ON = default_scenario(
    "head_on",
    ownship={
        "start": {"x": 200, "y": 1000, "h": 120, "heading_deg": 90, "speed_mps": 20},
        "goal": [1800, 1000, 120],
    },
    intruders={"list": [{"x": 1500, "y": 1000, "h": 120, "heading_deg": 270, "speed_mps": 22}]},
    avoidance={"max_steps": 200},
    surveillance={"model": "truth"},  # the setting the shipped models were trained in
)


def test_learned_planners_steer_off_a_head_on_collision_course() -> None:
    """Holding course collides; the trained policies keep clear of the intruder."""
    from uavxai.sim.build import run_kinematic as run_episode

    assert run_episode("none", HEAD_ON, 0).outcome == "collision"
    for name in ("dqn", "safe_dqn"):
        r = run_episode(name, HEAD_ON, 0)
        assert r.outcome != "collision", name
        assert r.min_separation_m > HEAD_ON.avoidance.d_min_m, name


@pytest.mark.xfail(
    strict=True,
    reason="the shipped checkpoints keep clear of the intruder but then wander and time out "
    "short of the goal on this route, not the scenario route they were trained on (see "
    "docs/results/README.md); strict, so a model that does reach it flags this marker",
)
def test_learned_planners_reach_the_goal_after_a_head_on_encounter() -> None:
    from uavxai.sim.build import run_kinematic as run_episode

    for name in ("dqn", "safe_dqn"):
        assert run_episode(name, HEAD_ON, 0).outcome == "goal", name


# ------------------------------------------------------------------------ checkpoint errors
def _expect_checkpoint_error(path: Path, algo: str, *words: str) -> None:
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(path, algo)
    msg = str(err.value)
    assert str(path) in msg
    for w in words:
        assert w in msg


def test_missing_checkpoint_names_the_file(tmp_path: Path) -> None:
    _expect_checkpoint_error(tmp_path / "nope.pt", "dqn", "no such file", "uavxai train")


def test_corrupt_checkpoint_names_the_file(tmp_path: Path) -> None:
    bad = tmp_path / "model.pt"
    bad.write_bytes(b"this is not a torch file")
    _expect_checkpoint_error(bad, "dqn", "not a readable torch checkpoint")
    other = tmp_path / "other.pt"
    torch.save({"weights": torch.zeros(3)}, other)
    _expect_checkpoint_error(other, "dqn", "not an avoidance checkpoint")


def test_mismatched_checkpoints_are_refused(tmp_path: Path) -> None:
    dqn = tmp_path / "dqn.pt"
    save_checkpoint(
        dqn, "dqn", {"q": QNetwork(obs_dim(4), (16,))}, hidden=(16,), n_nearest=4, meta={}
    )
    load_checkpoint(dqn, "dqn")  # a good one loads
    _expect_checkpoint_error(dqn, "safe_dqn", "trained for 'dqn'", "--algo safe_dqn")

    # Right algorithm, wrong network shape.
    wrong = tmp_path / "wrong.pt"
    save_checkpoint(
        wrong, "dqn", {"q": QNetwork(obs_dim(4), (8,))}, hidden=(16,), n_nearest=4, meta={}
    )
    _expect_checkpoint_error(wrong, "dqn", "wrong shape")

    # Trained on an observation that this code no longer computes.
    stale = tmp_path / "stale.pt"
    save_checkpoint(
        stale, "dqn", {"q": QNetwork(obs_dim(4), (16,))}, hidden=(16,), n_nearest=4, meta={}
    )
    ckpt = torch.load(stale, weights_only=True)
    ckpt["obs_probe"] = ckpt["obs_probe"] * 2.0
    torch.save(ckpt, stale)
    _expect_checkpoint_error(stale, "dqn", "observation that differs")


def test_scenario_checkpoint_errors_exit_2_through_the_cli(tmp_path: Path, capsys) -> None:
    scenario = tmp_path / "s.yaml"
    missing = tmp_path / "missing.pt"
    scenario.write_text(
        f"name: s\nintruders: {{count: 2}}\navoidance: {{planner: dqn, checkpoint: {missing}}}\n"
    )
    code = main(
        ["evaluate", str(scenario), "--methods", "dqn", "--intruders", "2", "--episodes", "1",
         "--out", str(tmp_path / "out")]
    )  # fmt: skip
    assert code == 2
    err = capsys.readouterr().err
    assert str(missing) in err and "Traceback" not in err
    code = main(
        ["train", str(scenario), "--stage", "avoidance", "--algo", "dqn", "--episodes", "1",
         "--out", str(tmp_path / "train")]
    )  # fmt: skip
    assert code == 2
    assert str(missing) in capsys.readouterr().err


@pytest.mark.parametrize("name", ["dqn", "safe_dqn"])
def test_learned_planners_check_inputs_and_measure_exactly(name: str) -> None:
    """The same input checks as the tree planners, and separations solved exactly (not the
    sampled minimum, which overstates a closest approach between sub-steps)."""
    from dataclasses import replace

    from uavxai.avoidance.mcts import intruder_arrays
    from uavxai.avoidance.model import EncounterModel, ownship_state
    from uavxai.errors import UserError

    planner = make_planner(name, CONFIG)
    with pytest.raises(UserError, match="non-finite"):
        planner.plan(replace(OWN, x=math.nan), [], GOAL)
    with pytest.raises(UserError, match="goal"):
        planner.plan(OWN, [], (0.0, math.inf, 120.0))
    # a crossing intruder whose closest approach (100 m) falls between two sub-step instants
    own_v = 20.0 * np.array([math.sin(OWN.heading), math.cos(OWN.heading)])
    rel_v = np.array([-25.0, 25.0]) - own_v
    normal = np.array([rel_v[1], -rel_v[0]]) / np.linalg.norm(rel_v)
    start = np.array([OWN.x, OWN.y]) + 100.0 * normal - 0.25 * rel_v
    intruders = [*_traffic(20, seed=5), Intruder(99, *start, 120.0, -25.0, 25.0)]
    d = planner.plan(OWN, intruders, GOAL)
    model = EncounterModel(CONFIG)
    pos, vel = intruder_arrays(intruders)
    period = CONFIG.decision_period_s
    flown = [
        model.fly(
            ownship_state(OWN)[None], np.array([d.action]), np.asarray(GOAL, dtype=float),
            period, model.predict(pos, vel, period), cull=False, exact=exact,
        ).min_sep[0]
        for exact in (True, False)
    ]  # fmt: skip
    assert flown[1] - flown[0] > 0.1  # sampling would overstate this one
    assert d.predicted_min_separation_m == pytest.approx(float(flown[0]), abs=1e-9)
    assert d.branch_min_separation_m == d.children[d.action].predicted_min_separation_m


@pytest.mark.parametrize("name", ["dqn", "safe_dqn"])
def test_learned_words_name_the_manoeuvre_flown_and_real_alternatives(name: str) -> None:
    """At the bank limit and the top speed, 'right' and 'faster' change nothing: the words
    say what a clamped action flies, and the why-not never offers the chosen manoeuvre
    under another name (even when the network ranks that twin second)."""
    from dataclasses import replace

    from uavxai.vocabulary import ACTIONS, HOLD

    own = replace(OWN, bank=CONFIG.bank_limit_rad, speed=CONFIG.speed_mps[1])
    planner = make_planner(name, CONFIG)
    children = planner.plan(own, _traffic(10, seed=2), GOAL).children
    right_faster = next(a.index for a in ACTIONS if (a.bank, a.accel) == (1, 1))
    assert children[right_faster].flies == HOLD  # both commands clamped
    twins = [c.action for c in children if c.flies == HOLD and c.action != right_faster]
    assert twins  # hold itself at least
    # the network's ranking: right/faster first, its twins next, real alternatives last
    order = [right_faster, *twins] + [a for a in range(N_ACTIONS) if children[a].flies != HOLD]
    ranked = np.zeros(N_ACTIONS)
    ranked[order] = np.linspace(1.0, 0.1, N_ACTIONS)
    q = {"q": ranked, "goal": ranked, "safety": np.ones(N_ACTIONS)}
    sentence, why_not = planner.explain(right_faster, q, children)
    assert "(flown as hold bank, hold speed: clamped at a limit)" in sentence
    named = why_not.removeprefix("why not ").split(":")[0].split(" (")[0]
    alternative = next(a for a in ACTIONS if a.name == named)
    assert children[alternative.index].flies != HOLD, why_not
