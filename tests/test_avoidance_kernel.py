"""The compiled MCTS loop (uavxai.avoidance.kernel) expands every node as the Python
expansion (TreeBuilder over EncounterModel.expand, which the exhaustive search uses) does."""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from uavxai.avoidance import Ownship, PlannerConfig
from uavxai.avoidance.mcts import TreeBuilder, predict_levels, search
from uavxai.avoidance.model import NONE, EncounterModel, ownship_state
from uavxai.scenario import default_scenario
from uavxai.sim.build import open_world
from uavxai.sim.spec import episode_spec
from uavxai.surveillance.tracker import truth_beliefs

# what the kernel and the Python expansion must agree on exactly, and to rounding
EXACT = ("parent", "action", "depth", "closest", "terminal", "first_child")
CLOSE = ("min_sep", "pos", "t_closest", "state")


# mcts_daa's conflict cylinder (uavxai.avoidance.planners._daa_config): the NMAC radius, the
# collision distance up and down
CYLINDER = {"conflict_volume": "cylinder", "d_min_m": 152.4, "conflict_half_height_m": 50.0}


def crowded(seed: int, n_intruders: int, actions: str, **settings):
    """A seeded crowded encounter: config, model, root, goal, tracks."""
    scenario = default_scenario("kernel-test", intruders={"count": n_intruders})
    cfg = dataclasses.replace(PlannerConfig.from_scenario(scenario), actions=actions, **settings)
    spec = episode_spec(scenario, seed, n_intruders=n_intruders)
    with open_world(spec) as world:
        intruders = truth_beliefs(world.state())
    heading = 0.7 * seed
    own = Ownship(900.0 + 40 * seed, 800.0, 115.0 + seed, 17.0 + seed, heading,
                  bank=math.radians(10.0 * (seed % 3 - 1)))  # fmt: skip
    model = EncounterModel(cfg)
    tracks = predict_levels(model, intruders, cfg.depth, cfg.action_hold_s)
    return cfg, model, ownship_state(own), np.asarray(spec.goal), tracks


@pytest.mark.parametrize("settings", [{}, CYLINDER], ids=["sphere", "cylinder"])
@pytest.mark.parametrize("actions", ["paper", "vertical"])
@pytest.mark.parametrize("seed", [0, 3, 7])
def test_every_node_the_kernel_expands_has_the_python_children(seed, actions, settings):
    cfg, model, root, goal, tracks = crowded(seed, 30, actions, **settings)
    hold = cfg.action_hold_s
    tree = search(model, root, goal, tracks, simulations=cfg.simulations, c=cfg.c,
                  hold_s=hold, rng=np.random.default_rng(seed), time_left_s=30.0)  # fmt: skip
    # Replay the kernel's expansions, in its order, through the Python expansion.
    builder = TreeBuilder(model, root, goal, tracks, hold, 30.0)
    expanded = np.flatnonzero(tree.first_child >= 0)
    for node in expanded[np.argsort(tree.first_child[expanded])]:
        assert builder.expand(int(node)) == tree.first_child[node]
    python = builder.finish()
    assert python.size == tree.size
    for field in EXACT:
        np.testing.assert_array_equal(getattr(tree, field), getattr(python, field), field)
    # the same arithmetic; the last bits of a few numbers differ (libm against numpy's SIMD)
    for field in CLOSE:
        np.testing.assert_allclose(
            getattr(tree, field), getattr(python, field), rtol=0, atol=1e-9, err_msg=field
        )
    # a search with something to find: conflicts and time-outs (at 30 s) among the lines
    assert (tree.terminal != NONE).any() and np.isfinite(tree.min_sep).any()
    assert int(tree.visits[0]) == cfg.simulations
