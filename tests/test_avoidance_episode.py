"""The kinematic episode runner, the engine as a Gymnasium environment and the planner
factory."""

from __future__ import annotations

import math
import sys

import numpy as np
import pytest

from uavxai.avoidance import Ownship, PlannerConfig, make_planner
from uavxai.avoidance.observation import observation_size, observe
from uavxai.avoidance.planners import PLANNERS
from uavxai.errors import UserError
from uavxai.learning.env import EncounterEnv
from uavxai.scenario import IntruderSpec, default_scenario
from uavxai.sim.build import run_kinematic as run_episode

HOLD = 4


def small_scenario(**avoidance):
    # The paper's setting: exact intruder states, the drawn traffic only.
    return default_scenario(
        "episode-test",
        surveillance={"model": "truth"},
        intruders={"flow": "none"},
        ownship={
            "start": {"x": 700, "y": 700, "h": 120, "heading_deg": 45, "speed_mps": 20},
            "goal": [1000, 1000, 100],
        },
        avoidance={"mcts": {"simulations": 40, "depth": 2, "action_hold_s": 3.0}, **avoidance},
    )


def test_same_seed_same_episode():
    sc = small_scenario()
    a = run_episode("mcts", sc, seed=5, n_intruders=15)
    b = run_episode("mcts", sc, seed=5, n_intruders=15)
    assert (a.outcome, a.steps, a.min_separation_m) == (b.outcome, b.steps, b.min_separation_m)
    np.testing.assert_array_equal(a.path, b.path)
    assert a.outcome in ("goal", "collision", "timeout", "out_of_bounds")
    assert len(a.decision_ms) == a.steps and a.path.shape == (a.steps + 1, 3)
    c = run_episode("mcts", sc, seed=6, n_intruders=15)
    assert not np.array_equal(a.path, c.path)


def test_planner_object_is_reset_to_the_episode_seed():
    sc = small_scenario()
    planner = make_planner("mcts", PlannerConfig.from_scenario(sc))
    first = run_episode(planner, sc, seed=3, n_intruders=10)
    second = run_episode(planner, sc, seed=3, n_intruders=10)
    np.testing.assert_array_equal(first.path, second.path)


def test_kinematic_predictions_match_what_is_flown():
    # Straight intruders and the same model: the next-period prediction is exact up to the
    # chords: the planner's sub-steps are 0.5 s, the engine samples at 10 Hz, and a 0.5 s arc
    # at 20 m/s and 30 deg bank strays 0.18 m from its chord.
    r = run_episode("none", small_scenario(), seed=2, n_intruders=10)
    assert r.separation_error_m and max(r.separation_error_m) < 0.2


def encounter(intruders, goal, start: Ownship, **avoidance) -> tuple[EncounterEnv, dict]:
    """The engine's env on the default scenario, and the reset options for these intruders,
    goal and start."""
    sc = default_scenario("env-test", avoidance=avoidance)
    return EncounterEnv(sc), {"intruders": intruders, "goal": goal, "start": start}


def test_env_goal_reward_and_termination():
    env, options = encounter([], (1000.0, 1100.0, 120.0), Ownship(1000, 1000, 120, 20, 0.0))
    obs, info = env.reset(seed=0, options=options)
    assert obs.shape == env.observation_space.shape and info["distance_m"] == pytest.approx(100)
    rewards, done = [], False
    while not done:
        obs, reward, terminated, truncated, info = env.step(HOLD)
        rewards.append(reward)
        done = terminated or truncated
    assert terminated and info["outcome"] == "goal"
    assert rewards[-1] == 1.0 and sum(rewards[:-1]) == 0.0
    assert env.t < 3.0  # 50 m to the goal circle at 20 m/s
    with pytest.raises(RuntimeError, match="over"):
        env.step(HOLD)


def test_env_time_out_is_a_truncation_worth_0_1():
    env, options = encounter(
        [], (1900.0, 1900.0, 120.0), Ownship(100, 100, 120, 20, 0.8), max_steps=3
    )
    env.reset(seed=0, options=options)
    for _ in range(3):
        *_, reward, terminated, truncated, info = env.step(HOLD)
    assert truncated and not terminated and reward == pytest.approx(0.1)
    assert info["outcome"] == "timeout"


def test_env_collision_and_leaving_the_area():
    head_on = [IntruderSpec(x=1000, y=1150, h=120, heading_deg=180, speed_mps=20)]
    env, options = encounter(head_on, (1000, 1900, 120), Ownship(1000, 1000, 120, 20, 0))
    env.reset(seed=0, options=options)
    for _ in range(5):
        _, reward, terminated, _, info = env.step(HOLD)
        if terminated:
            break
    assert info["outcome"] == "collision" and reward == 0.0
    assert info["min_separation_m"] < 50.0
    env, options = encounter([], (1000, 1000, 120), Ownship(1990, 500, 120, 20, 1.57))
    env.reset(seed=0, options=options)
    *_, reward, terminated, _, info = env.step(HOLD)
    assert terminated and info["outcome"] == "out_of_bounds" and reward == 0.0


def test_turning_intruders_turn():
    turning = [IntruderSpec(x=500, y=500, h=120, heading_deg=0, speed_mps=20,
                            behaviour="random_turns")]  # fmt: skip
    env = EncounterEnv(small_scenario())
    start = Ownship(100, 100, 120, 20, 0)
    env.reset(seed=0, options={"intruders": turning, "goal": (1000, 1000, 120), "start": start})
    headings = []
    for _ in range(30):
        env.step(HOLD)
        headings.append(env.intruders[0].vx)
    assert np.ptp(headings) > 1.0  # it does turn


def test_observation_size_is_independent_of_the_intruder_count():
    cfg = PlannerConfig()
    own = np.array([1000.0, 1000.0, 120.0, 20.0, 0.0, 0.0, 0.0])
    sizes = set()
    for n in (0, 3, 40):
        pos = np.c_[np.linspace(1100, 1900, n), np.full(n, 1000.0), np.full(n, 120.0)]
        obs = observe(own, pos, np.zeros((n, 3)), np.array([1500.0, 1500.0, 120.0]), cfg, 5)
        sizes.add(obs.shape)
    assert sizes == {(observation_size(5),)}
    # nearest first: slot 0 is the intruder 100 m east, i.e. 100 m to the right of a north heading
    pos = np.array([[1900.0, 1000.0, 120.0], [1100.0, 1000.0, 120.0]])
    obs = observe(own, pos, np.zeros((2, 3)), np.array([1500.0, 1500.0, 120.0]), cfg, 5)
    first = obs[10:18]
    assert first[1] == pytest.approx(100 / 500) and first[7] == 1.0
    assert obs[10 + 2 * 8 + 7] == 0.0  # third slot absent


def test_planner_factory():
    cfg = PlannerConfig()
    for name in ("mcts", "mcts_fast", "exhaustive", "none"):
        planner = make_planner(name, cfg)
        assert planner.name == name
        d = planner.plan(Ownship(500, 500, 120, 20, 0.7), [], (1000, 1000, 100))
        assert 0 <= d.action < 9 and d.planner == name
    fast = make_planner("mcts_fast", cfg)
    assert (fast.config.simulations, fast.config.depth) == (40, 2)
    with pytest.raises(UserError, match="unknown avoidance planner 'mtcs'"):
        make_planner("mtcs", cfg)
    assert set(PLANNERS) >= {"dqn", "safe_dqn"}


def test_learned_planners_missing_is_a_user_error(monkeypatch):
    monkeypatch.setitem(sys.modules, "uavxai.avoidance.learned", None)
    with pytest.raises(UserError, match="learned baselines"):
        make_planner("dqn", PlannerConfig())


def test_bad_planner_config_is_a_user_error():
    with pytest.raises(UserError, match="simulations"):
        PlannerConfig(simulations=0)
    with pytest.raises(UserError, match="speed_mps"):
        PlannerConfig(speed_mps=(30.0, 12.0))


def test_direct_planner_steers_at_the_goal():
    planner = make_planner("none", PlannerConfig())
    goal = (1500.0, 1000.0, 120.0)  # due east of an ownship flying north
    own = Ownship(1000, 1000, 120, 20, 0.0)
    assert planner.plan(own, [], goal).action // 3 == 2  # bank right
    own = Ownship(1000, 1000, 120, 20, math.pi / 2)  # already pointing at it
    assert planner.plan(own, [], goal).action // 3 == 1  # hold


@pytest.mark.slow
def test_mcts_avoids_what_flying_straight_runs_into():
    """30 seeded episodes among 40 intruders (about a minute)."""
    sc = default_scenario("slow")
    outcomes = {
        name: [run_episode(name, sc, seed, 40).outcome for seed in range(30)]
        for name in ("none", "mcts")
    }
    assert outcomes["none"].count("collision") >= 5  # the traffic is a real threat
    assert outcomes["mcts"].count("collision") <= 2
    assert outcomes["mcts"].count("goal") >= 27


@pytest.mark.filterwarnings("ignore:.*Box observation space:UserWarning")
def test_env_passes_the_gymnasium_checker():
    from gymnasium.utils.env_checker import check_env

    env = EncounterEnv(small_scenario(), n_intruders=8)
    check_env(env, skip_render_check=True)
    a, _ = env.reset(seed=4)
    b, _ = env.reset(seed=4)
    np.testing.assert_array_equal(a, b)
    c, _ = env.reset(seed=5)
    assert not np.array_equal(a, c)  # fresh intruders per seed
