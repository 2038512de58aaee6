"""The service-point environment's Gymnasium contract."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

from uavxai.scenario import default_scenario
from uavxai.service.service_env import (
    HOVER,
    MOVE_NAMES,
    MOVES,
    SearchSpace,
    ServiceEnv,
    levels_to_power,
)


def make_env(**comms) -> ServiceEnv:
    sc = default_scenario(
        comms={"users": {"count": 4}, "fading": "none", "power_levels": 4, **comms},
        service={"steps": 12, "step_m": 50},
    )
    return ServiceEnv.from_scenario(sc)


def hover(env: ServiceEnv, level: int = 1) -> np.ndarray:
    return np.array([HOVER] + [level] * env.channel.k)


def test_spaces_and_reset():
    env = make_env()
    assert isinstance(env.action_space, gym.spaces.MultiDiscrete)
    assert env.action_space.nvec.tolist() == [7, 4, 4, 4, 4]
    assert env.observation_space.shape == (3 + 4,)
    obs, info = env.reset(seed=3)
    assert env.observation_space.contains(obs)
    # the region's centre at h = 100 m; normalised within the box x, y [750, 1250], h [50, 300]
    np.testing.assert_allclose(info["position"], [1000.0, 1000.0, 100.0])
    np.testing.assert_allclose(obs[:3], [0.0, 0.0, 2 * 50 / 250 - 1], atol=1e-6)
    # gain features: dB relative to free space at 100 m, over 10 -> a few units below zero
    assert (obs[3:] < 0.5).all() and (obs[3:] > -5).all()


def test_moves_are_step_m_in_the_named_direction():
    assert MOVE_NAMES == ("left", "right", "forward", "back", "up", "down", "hover")
    env = make_env()
    for move in range(7):
        env.reset()
        action = hover(env)
        action[0] = move
        _, _, _, _, info = env.step(action)
        np.testing.assert_allclose(info["position"] - env.space.start, MOVES[move] * 50.0)
        assert not info["refused"]


def test_out_of_bounds_moves_are_refused_and_penalised():
    env = make_env()
    env.reset()
    # down: 100 -> 50 -> (0, below world.h[0] = 50): the second is refused
    down = hover(env)
    down[0] = MOVE_NAMES.index("down")
    env.step(down)
    obs_before = env._observe()
    _, r_refused, _, _, info = env.step(down)
    assert info["refused"]
    np.testing.assert_allclose(info["position"], [1000.0, 1000.0, 50.0])
    _, r_hover, _, _, info_h = env.step(hover(env))
    assert not info_h["refused"]
    assert r_refused == pytest.approx(r_hover / 2.0)
    np.testing.assert_array_equal(env._observe(), obs_before)
    # the search box edge in x: 1000 + 5 * 50 = 1250 allowed, 1300 refused
    env.reset()
    right = hover(env)
    right[0] = MOVE_NAMES.index("right")
    for _ in range(5):
        assert not env.step(right)[4]["refused"]
    assert env.step(right)[4]["refused"]
    assert env.position[0] == pytest.approx(1250.0)


def test_power_levels_scaled_to_p_max():
    L, p_max = 6, 2.0
    # all at the top level: an equal share of P_max
    np.testing.assert_allclose(levels_to_power(np.full(4, 5), p_max, L), np.full(4, 0.5))
    # one user at the top level gets all of it; level 0 gets nothing
    np.testing.assert_allclose(levels_to_power(np.array([5, 0, 0]), p_max, L), [2.0, 0, 0])
    # sums at most L - 1 are not scaled: l / (L - 1) of P_max each
    np.testing.assert_allclose(levels_to_power(np.array([1, 2, 0]), p_max, L), [0.4, 0.8, 0])
    # above that, proportional: [3, 4, 1] -> 2 * [3, 4, 1] / 8
    np.testing.assert_allclose(levels_to_power(np.array([3, 4, 1]), p_max, L), [0.75, 1.0, 0.25])
    levels = np.random.default_rng(0).integers(0, L, size=(1000, 10))
    assert (levels_to_power(levels, p_max, L).sum(axis=1) <= p_max + 1e-12).all()


def test_reward_is_the_objective_and_the_env_keeps_the_best_point():
    env = make_env()
    env.reset()
    action = hover(env, level=3)
    _, reward, terminated, truncated, info = env.step(action)
    power = levels_to_power(action[1:], env.channel.p_max_w, env.power_levels)
    link = env.channel.evaluate(env.space.start, power)
    assert reward == pytest.approx(float(link.objective))
    assert info["objective"] == pytest.approx(float(link.objective))
    assert not terminated and not truncated
    # starving user 0 costs its rate and halves the rest: the best point stays the first
    starve = action.copy()
    starve[1] = 0
    _, r2, _, _, _ = env.step(starve)
    assert r2 < reward
    assert env.best["objective"] == pytest.approx(reward)
    np.testing.assert_array_equal(env.best["levels"], action[1:])


def test_truncation_after_steps_and_invalid_actions():
    env = make_env()
    env.reset()
    for t in range(12):
        *_, truncated, _ = env.step(hover(env))
        assert truncated == (t == 11)
    assert len(env.path) == 13
    with pytest.raises(ValueError, match="not in"):
        env.step(np.array([7, 0, 0, 0, 0]))
    with pytest.raises(ValueError, match="not in"):
        env.step(np.array([0, 0, 0]))


def test_fading_rewards_repeat_with_the_seed():
    env = make_env(fading="rayleigh")
    env.action_space.seed(5)
    actions = [env.action_space.sample() for _ in range(8)]

    def run(seed: int) -> list[float]:
        env.reset(seed=seed)
        return [env.step(a)[1] for a in actions]

    assert run(1) == run(1)
    assert run(1) != run(2)


def test_lattice_axes_cover_the_box_from_the_start():
    sc = default_scenario(service={"step_m": 10})
    xs, ys, hs = SearchSpace.from_scenario(sc).axes()
    assert (len(xs), len(ys), len(hs)) == (51, 51, 26)
    assert xs[0] == 750 and xs[-1] == 1250 and hs[0] == 50 and hs[-1] == 300
    assert 100.0 in hs
