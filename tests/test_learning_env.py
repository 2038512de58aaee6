"""The avoidance env is honest to Gymnasium (issue 29): it passes Gymnasium's own checker, it
returns the observation the learned planners' networks see and pays the paper's eq 14 reward
(training's shaping is a wrapper), start and goal come through reset(options), and training's
envs are a gymnasium.vector env that repeats with its seed."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
import torch
from gymnasium.utils.env_checker import check_env

from uavxai.avoidance.learned import DQNPlanner
from uavxai.avoidance.model import terminal_value
from uavxai.avoidance.observation import observation_size
from uavxai.learning.env import EncounterEnv
from uavxai.learning.train import Hyperparameters, training_env, training_envs
from uavxai.scenario import Start, default_scenario

SCENARIO = default_scenario("env-test", intruders={"count": 6})
HP = Hyperparameters(intruders=(3, 6), n_envs=2, sample_hz=2.0)


def test_gymnasium_env_checker_passes_on_the_env_and_on_trainings_wrapped_env() -> None:
    check_env(EncounterEnv(SCENARIO, sample_hz=2.0), skip_render_check=True)
    check_env(training_env(SCENARIO, HP), skip_render_check=True)


def test_the_env_observation_is_what_the_shipped_networks_see() -> None:
    planner = DQNPlanner(EncounterEnv(SCENARIO).config)  # the shipped DQN
    env = EncounterEnv(SCENARIO, n_nearest=planner.n_nearest, sample_hz=2.0)
    assert env.observation_space.shape == (observation_size(planner.n_nearest),)
    obs, _ = env.reset(seed=3)
    for _ in range(5):
        # the env's observation, fed to the network, picks what the planner itself decides
        with torch.no_grad():
            q = planner.nets["q"](torch.as_tensor(obs)[None])[0].numpy()
        decision = planner.plan(env.ownship, env.intruders, tuple(env.goal))
        assert int(np.argmax(q)) == decision.action
        assert env.observation_space.contains(obs)
        obs, *_ = env.step(decision.action)


def test_the_env_pays_eq_14_and_the_shaping_wrapper_says_both_rewards() -> None:
    env = EncounterEnv(SCENARIO, sample_hz=2.0)
    env.reset(seed=1, options={"n_intruders": 2})
    rewards, info, done = [], {}, False
    while not done:
        _, r, terminated, truncated, info = env.step(0)
        rewards.append(r)
        done = terminated or truncated
    assert rewards[:-1] == [0.0] * (len(rewards) - 1)
    assert rewards[-1] == terminal_value(info["outcome"])

    shaped = training_env(SCENARIO, HP)
    shaped.reset(seed=1)
    _, r, _, _, info = shaped.step(4)
    assert r == pytest.approx(info["reward_goal"] + info["reward_safety"])
    assert info["eq14_reward"] == 0.0 and r != 0.0


def test_start_and_goal_come_through_reset_options() -> None:
    env = EncounterEnv(SCENARIO, sample_hz=2.0)
    start = Start(x=500.0, y=700.0, h=110.0, heading_deg=90.0, speed_mps=20.0)
    env.reset(seed=0, options={"start": start, "goal": (1500.0, 700.0, 110.0), "n_intruders": 1})
    own = env.ownship
    assert (own.x, own.y, own.h) == pytest.approx((500.0, 700.0, 110.0))
    assert tuple(env.goal) == (1500.0, 700.0, 110.0)
    assert len(env.intruders) == 1
    with pytest.raises(ValueError, match="unknown; allowed: start, goal"):
        env.reset(seed=0, options={"goal_xyz": (0, 0, 0)})


def _rollout(steps: int) -> tuple[list[np.ndarray], list[str]]:
    envs = training_envs(SCENARIO, HP)
    assert isinstance(envs, gym.vector.SyncVectorEnv) and envs.num_envs == HP.n_envs
    obs, _ = envs.reset(seed=HP.seed)
    seen, ends = [obs], []
    for t in range(steps):
        obs, _, terminated, truncated, infos = envs.step(np.array([t % 9, (t * 4) % 9]))
        seen.append(obs)
        for i in np.flatnonzero(terminated | truncated):
            ends.append(str(infos["final_info"]["outcome"][i]))
    envs.close()
    return seen, ends


def test_trainings_vector_env_resets_itself_and_repeats_with_its_seed() -> None:
    a, ends_a = _rollout(120)
    b, ends_b = _rollout(120)
    assert ends_a and ends_a == ends_b  # episodes ended and the envs went on (auto-reset)
    assert all(np.array_equal(x, y) for x, y in zip(a, b, strict=True))
