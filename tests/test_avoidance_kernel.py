"""The compiled MCTS (uavxai.avoidance.kernel) builds the Python search's tree, node by node."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from uavxai.avoidance import Ownship, PlannerConfig
from uavxai.avoidance.mcts import MCTSPlanner
from uavxai.learning.env import default_goal, episode_intruders
from uavxai.scenario import default_scenario
from uavxai.sim.kinematic import KinematicWorld
from uavxai.surveillance.tracker import truth_beliefs

EXACT = ("parent", "action", "depth", "visits", "closest", "terminal", "first_child")
CLOSE = ("value_sum", "min_sep", "pos", "t_closest", "state")


def encounter(seed: int, n_intruders: int):
    scenario = default_scenario("kernel-test", intruders={"count": n_intruders})
    rng = np.random.default_rng(1000 + seed)
    own = Ownship(
        x=float(rng.uniform(200, 1800)),
        y=float(rng.uniform(200, 1800)),
        h=float(rng.uniform(100, 140)),
        speed=float(rng.uniform(15, 28)),
        heading=float(rng.uniform(0, 2 * math.pi)),
        bank=math.radians(float(rng.choice([-20, -10, 0, 10, 20]))),
    )
    with KinematicWorld(scenario, episode_intruders(scenario, seed, n_intruders)) as world:
        intruders = truth_beliefs(world.state())
    return PlannerConfig.from_scenario(scenario), (own, intruders, default_goal(scenario))


@pytest.mark.parametrize("actions", ["paper", "vertical"])
@pytest.mark.parametrize("seed", [0, 3, 7])
def test_kernel_tree_is_the_python_tree(seed, actions):
    cfg, case = encounter(seed, 30)
    cfg = dataclasses.replace(cfg, actions=actions)
    compiled, python = MCTSPlanner(cfg), MCTSPlanner(cfg, compiled=False)
    compiled.reset(seed)
    python.reset(seed)
    a, b = compiled.plan(*case), python.plan(*case)
    assert a.action == b.action
    assert a.tree.size == b.tree.size
    for field in EXACT:
        np.testing.assert_array_equal(getattr(a.tree, field), getattr(b.tree, field), field)
    # the same arithmetic; the last bits of a few numbers differ (libm against numpy's SIMD)
    for field in CLOSE:
        np.testing.assert_allclose(
            getattr(a.tree, field), getattr(b.tree, field), rtol=0, atol=1e-9, err_msg=field
        )
    assert [c.visits for c in a.children] == [c.visits for c in b.children]
    # the tree holds events: collisions, time-outs or the goal, not only open lines
    assert (a.tree.terminal != 0).any() or np.isfinite(a.tree.min_sep).any()
