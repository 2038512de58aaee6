"""DQN baseline: the network and training loop of ``d3qn.py`` without its two improvements.

- no dueling: each branch's head outputs its Q-values directly (no shared V(s));
- no double DQN: the target network both picks and values the next action,
  ``y = r + gamma * mean_d max_a Q_d^target(s', a)``.

Everything else (branching heads, replay, epsilon schedule, hyper-parameters) is identical, so
the learning curves isolate what dueling + double add.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass

from uavxai.service import d3qn
from uavxai.service.service_env import ServiceEnv


@dataclass
class DQNConfig(d3qn.D3QNConfig):
    dueling: bool = False
    double: bool = False


def train(
    env: ServiceEnv | Callable[[int], ServiceEnv],
    cfg: DQNConfig | None = None,
    on_episode: Callable[[int, dict[str, float]], None] | None = None,
) -> d3qn.TrainResult:
    return d3qn.train(env, cfg or DQNConfig(), on_episode=on_episode)
