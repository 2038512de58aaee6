"""Collision avoidance: the encounter model, MCTS and its baselines, and the episode runner.

The planner API (SPEC §7) works without JSBSim, MAVLink or rerun::

    from uavxai.avoidance import MCTSPlanner, PlannerConfig, Ownship, Intruder
    decision = MCTSPlanner(PlannerConfig()).plan(own, intruders, goal)
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

__all__ = [
    "ChildStats",
    "Decision",
    "Intruder",
    "MCTSPlanner",
    "Ownship",
    "Planner",
    "PlannerConfig",
    "SearchTree",
]
