"""Avoidance planners by name: the factory behind `avoidance.planner`, `uavxai evaluate
--methods` and the pipeline.

Every planner follows :class:`uavxai.avoidance.types.Planner`: ``plan(own, intruders, goal,
*, step) -> Decision`` and ``reset(seed)``, with ``name`` and ``config`` attributes. The
learned ones (``dqn``, ``safe_dqn``) live in :mod:`uavxai.avoidance.learned`, imported only
when asked for (it needs torch), through ``make_learned_planner(name, config, checkpoint)``.
"""

from __future__ import annotations

import dataclasses
from pathlib import Path

from uavxai.avoidance.direct import DirectPlanner
from uavxai.avoidance.exhaustive import ExhaustivePlanner
from uavxai.avoidance.mcts import MCTSPlanner
from uavxai.avoidance.types import Planner, PlannerConfig
from uavxai.errors import UserError

PLANNERS = ("mcts", "mcts_fast", "exhaustive", "dqn", "safe_dqn", "none")
LEARNED = ("dqn", "safe_dqn")

# The paper's Tree-fast: few simulations, a shallow tree, short holds.
TREE_FAST = {"simulations": 40, "depth": 2, "action_hold_s": 2.0}


def fast_config(config: PlannerConfig) -> PlannerConfig:
    """``config`` with the Tree-fast search settings."""
    return dataclasses.replace(config, **TREE_FAST)


def make_planner(
    name: str, config: PlannerConfig | None = None, checkpoint: str | Path | None = None
) -> Planner:
    """The planner called ``name`` (one of PLANNERS) with ``config``; ``checkpoint`` is the
    model.pt of a learned planner (None: the shipped one) and is ignored by the others."""
    config = config or PlannerConfig()
    if name == "mcts":
        return MCTSPlanner(config)
    if name == "mcts_fast":
        return MCTSPlanner(fast_config(config), name="mcts_fast")
    if name == "exhaustive":
        return ExhaustivePlanner(config)
    if name == "none":
        return DirectPlanner(config)
    if name in LEARNED:
        try:
            from uavxai.avoidance.learned import make_learned_planner
        except ModuleNotFoundError as exc:
            if exc.name not in ("uavxai.avoidance.learned", "torch"):
                raise
            raise UserError(
                f"avoidance planner '{name}' needs the learned baselines "
                f"(uavxai.avoidance.learned and torch), which are not available: {exc}. "
                f"Use one of {', '.join(p for p in PLANNERS if p not in LEARNED)}."
            ) from None
        return make_learned_planner(name, config, checkpoint)
    raise UserError(f"unknown avoidance planner '{name}'; choose one of {', '.join(PLANNERS)}.")
