"""D3QN / DQN: network structure, the TD targets, a short training run, checkpoints."""

from __future__ import annotations

import copy

import numpy as np
import pytest
import torch

from uavxai.errors import CheckpointError
from uavxai.learning import branching, checkpoint
from uavxai.learning.service import episodes_to_converge
from uavxai.scenario import default_scenario
from uavxai.service import d3qn
from uavxai.service.grid import solve_grid
from uavxai.service.service_env import ServiceEnv


def tiny_env(seed: int = 0, access: str = "ofdma") -> ServiceEnv:
    sc = default_scenario(
        seed=seed,
        comms={"users": {"count": 3}, "power_levels": 3, "access": access, "fading": "none"},
        service={"steps": 20, "step_m": 25},
    )
    return ServiceEnv.from_scenario(sc)


def test_branching_dueling_network():
    torch.manual_seed(0)
    net = d3qn.BranchingQNetwork(
        obs_dim=13, k=10, power_levels=6, hidden=40, layers=3, dueling=True
    )
    hidden = [m for m in net.trunk if isinstance(m, torch.nn.Linear)]
    assert [(m.in_features, m.out_features) for m in hidden] == [(13, 40), (40, 40), (40, 40)]
    obs = torch.randn(5, 13)
    move, power = net(obs)
    assert move.shape == (5, 7) and power.shape == (5, 10, 6)
    # dueling: every branch's Q-values average to the shared state value V(s)
    v = net.value(net.trunk(obs))
    torch.testing.assert_close(move.mean(-1, keepdim=True), v)
    torch.testing.assert_close(power.mean(-1), v.expand(5, 10))
    plain = d3qn.BranchingQNetwork(13, 10, 6, 40, 3, dueling=False)
    assert plain.value is None
    assert branching.DQNConfig().dueling is False and branching.DQNConfig().double is False


@pytest.mark.parametrize("double", [True, False])
def test_td_target_by_hand(double):
    """One update with lr = 0 returns the loss; recompute it from the two networks' outputs."""
    torch.manual_seed(1)
    cfg = branching.D3QNConfig(learning_rate=0.0, gamma=0.9, double=double)
    q = d3qn.BranchingQNetwork(5, 2, 3, 8, 2, dueling=True)
    target = copy.deepcopy(q)
    with torch.no_grad():  # make the target differ so that double and plain targets differ
        for p in target.parameters():
            p.add_(0.3 * torch.randn_like(p))
    obs, next_obs = torch.randn(4, 5), torch.randn(4, 5)
    actions = torch.tensor([[0, 1, 2], [6, 0, 0], [3, 2, 1], [1, 1, 1]])
    rewards = torch.tensor([1.0, 0.5, 0.0, 2.0])
    dones = torch.tensor([0.0, 0.0, 1.0, 0.0])
    loss = branching._update(
        q,
        target,
        torch.optim.Adam(q.parameters(), lr=0.0),
        {"obs": obs, "action": actions, "reward": rewards, "next_obs": next_obs, "done": dones},
        cfg,
    )
    with torch.no_grad():
        mt, pt = target(next_obs)
        if double:
            mo, po = q(next_obs)
            nm = mt[torch.arange(4), mo.argmax(1)]
            npw = torch.stack([pt[torch.arange(4), j, po[:, j].argmax(1)] for j in range(2)], 1)
        else:
            nm, npw = mt.max(1).values, pt.max(2).values
        y = rewards + 0.9 * (1 - dones) * (nm + npw.sum(1)) / 3
        m, p = q(obs)
        qm = m[torch.arange(4), actions[:, 0]]
        qp = torch.stack([p[torch.arange(4), j, actions[:, 1 + j]] for j in range(2)], 1)
        expected = (((qm - y) ** 2).mean() + ((qp - y[:, None]) ** 2).mean(0).sum()) / 3
    assert loss == pytest.approx(float(expected), rel=1e-5)


def test_short_training_beats_the_random_policy():
    """60 episodes of 20 steps (a few seconds): the greedy policy earns far more per step than
    uniformly random actions, and its service point is most of the way to the optimum."""
    env = tiny_env(seed=0)
    optimum = solve_grid(env.channel, env.space, 3).objective
    env.action_space.seed(0)
    env.reset(seed=0)
    random_reward = np.mean([env.step(env.action_space.sample())[1] for _ in range(2000)])
    result = branching.train(env, branching.D3QNConfig(episodes=60, learning_starts=200, seed=0))
    greedy = d3qn.rollout(result.net, d3qn.fading_free(env))
    assert greedy.ret / env.steps > 1.3 * random_reward
    assert greedy.objective > 0.8 * optimum
    assert greedy.objective <= optimum * (1 + 1e-12)  # the grid optimum bounds every search
    assert len(result.curve) == 60
    assert result.best.objective >= greedy.objective or result.best.objective > 0


def test_training_is_reproducible():
    def run():
        cfg = branching.D3QNConfig(episodes=8, learning_starts=50)
        return branching.train(tiny_env(seed=2), cfg)

    a, b = run(), run()
    assert [r["greedy_objective"] for r in a.curve] == [r["greedy_objective"] for r in b.curve]
    for pa, pb in zip(a.net.parameters(), b.net.parameters(), strict=True):
        torch.testing.assert_close(pa, pb, rtol=0, atol=0)


def test_checkpoint_roundtrip(tmp_path):
    net = d3qn.BranchingQNetwork(6, 3, 3, 40, 3, dueling=True)
    path = tmp_path / "model.pt"
    meta = {"scenario": "x", "seed": 3}
    branching.save_checkpoint(path, net, "d3qn", branching.D3QNConfig(), meta)
    loaded, info = d3qn.load_checkpoint(path)
    assert info["algo"] == "d3qn" and info["k"] == 3 and info["meta"]["seed"] == 3
    obs = torch.randn(2, 6)
    torch.testing.assert_close(loaded(obs)[1], net(obs)[1])


def test_checkpoint_errors_name_the_file(tmp_path):
    missing = tmp_path / "nope.pt"
    with pytest.raises(CheckpointError, match="nope.pt: no such file"):
        d3qn.load_checkpoint(missing)
    garbage = tmp_path / "garbage.pt"
    garbage.write_bytes(b"this is not a model")
    with pytest.raises(CheckpointError, match="garbage.pt: not a readable torch checkpoint"):
        d3qn.load_checkpoint(garbage)
    foreign = tmp_path / "foreign.pt"
    torch.save({"weights": torch.zeros(3)}, foreign)
    with pytest.raises(CheckpointError, match="foreign.pt: not a uavxai service-point model"):
        d3qn.load_checkpoint(foreign)
    damaged = tmp_path / "damaged.pt"
    torch.save({"format": checkpoint.FORMATS["branching"][0], "k": 3}, damaged)
    # a model file without its sizes: the field and what is allowed are named (the size guard)
    with pytest.raises(CheckpointError, match=r"damaged.pt: obs_dim = None; allowed: an integer"):
        d3qn.load_checkpoint(damaged)


def test_episodes_to_converge():
    # rises linearly over 100 episodes, then flat at 1.0 for 100
    curve = np.concatenate([np.linspace(0.0, 1.0, 100), np.ones(100)])
    episode, final = episodes_to_converge(curve)
    assert final == pytest.approx(1.0)
    # running mean over 10 within 5 % of 1.0: from the episode where it reaches 0.95
    smooth_ok = next(i for i in range(200) if curve[max(0, i - 9) : i + 1].mean() >= 0.95)
    assert episode == smooth_ok + 1
    assert episodes_to_converge(np.ones(30))[0] == 1
