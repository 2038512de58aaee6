"""The one replay buffer of every trainer (avoidance DQN / Safe-DQN, the service D3QN / DQN,
the universal placement network): a ring of named transition fields, sampled uniformly.

Each trainer declares its fields once (shape of one transition and dtype), e.g. the
avoidance trainer's ``obs``, ``action``, ``reward`` (goal, safety), ``next_obs`` and
``discount``, and adds whole transitions; the oldest is overwritten once the ring is full.
:func:`n_step_return` folds the last n steps of an episode into one transition.
"""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import torch


class ReplayBuffer:
    """``size`` transitions of the named ``fields`` (name -> (shape, dtype))."""

    def __init__(self, size: int, fields: dict[str, tuple[tuple[int, ...], type]]) -> None:
        if size < 1:
            raise ValueError(f"a replay buffer holds at least 1 transition, not {size}")
        self.size = size
        self.data = {k: np.zeros((size, *shape), dtype) for k, (shape, dtype) in fields.items()}
        self.cursor = 0
        self.stored = 0

    def __len__(self) -> int:
        return self.stored

    def add(self, **transition: np.ndarray | float) -> None:
        """Store one transition: a value for every field, no other."""
        if transition.keys() != self.data.keys():
            raise ValueError(
                f"a transition has the fields {sorted(self.data)}, not {sorted(transition)}"
            )
        for k, v in transition.items():
            self.data[k][self.cursor] = v
        self.cursor = (self.cursor + 1) % self.size
        self.stored = min(self.stored + 1, self.size)

    def sample(self, rng: np.random.Generator, batch_size: int) -> dict[str, torch.Tensor]:
        """A uniform batch (with replacement) of the stored transitions, one tensor a field."""
        if not self.stored:
            raise ValueError("cannot sample an empty replay buffer")
        idx = rng.integers(0, self.stored, size=batch_size)
        return {k: torch.as_tensor(v[idx]) for k, v in self.data.items()}


def n_step_return(rewards: Sequence[np.ndarray | float], gamma: float) -> np.ndarray:
    """The discounted sum ``sum_k gamma^k r_k`` of consecutive rewards (each a scalar or a
    vector of reward parts), oldest first."""
    ret = np.zeros_like(np.asarray(rewards[0], dtype=float))
    for k, r in enumerate(rewards):
        ret = ret + gamma**k * np.asarray(r, dtype=float)
    return ret
