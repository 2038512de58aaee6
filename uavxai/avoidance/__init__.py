"""Collision avoidance: the encounter model, MCTS and its baselines (the planner API).

The planner API (README, "Using the planner in another simulator") works without JSBSim,
MAVLink or rerun::

    from uavxai.avoidance import MCTSPlanner, PlannerConfig, Ownship, Intruder
    decision = MCTSPlanner(PlannerConfig()).plan(own, intruders, goal)

``make_planner(name, config)`` builds any of them by name (mcts, mcts_fast, exhaustive, none,
and the learned dqn / safe_dqn).
"""

from uavxai.avoidance.types import (  # noqa: I001  (types first: the planners import them)
    ChildStats,
    Decision,
    Intruder,
    Ownship,
    Planner,
    PlannerConfig,
    SearchTree,
)
from uavxai.avoidance.mcts import MCTSPlanner
from uavxai.avoidance.planners import PLANNERS, make_planner

__all__ = [
    "PLANNERS",
    "ChildStats",
    "Decision",
    "Intruder",
    "MCTSPlanner",
    "Ownship",
    "Planner",
    "PlannerConfig",
    "SearchTree",
    "make_planner",
]
