"""Exhaustive search: the optimum over every action sequence, checked by brute force."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.avoidance import Intruder, MCTSPlanner, Ownship, PlannerConfig
from uavxai.avoidance.exhaustive import ExhaustivePlanner
from uavxai.avoidance.model import GOAL as GOAL_CODE
from uavxai.avoidance.model import NONE, TERMINAL_VALUE, EncounterModel, ownship_state

GOAL = (1000.0, 1500.0, 120.0)
OWN = Ownship(1000.0, 900.0, 120.0, 20.0, 0.0)
# An intruder crossing from the right just ahead, and one coming head-on a little left.
INTRUDERS = [
    Intruder(3, 1150.0, 1020.0, 120.0, -20.0, 0.0),
    Intruder(8, 960.0, 1200.0, 120.0, 0.0, -15.0),
]
# The brute force below predicts as the paper does: constant velocity, every collision 0.
PAPER = {"intruder_model": "cv", "late_collision_value": 0.0}


def brute_force_values(cfg: PlannerConfig) -> np.ndarray:
    """Value of every action pair (9, 9), each segment flown separately and exactly."""
    model = EncounterModel(cfg)
    hold = cfg.action_hold_s
    pos = np.array([[i.x, i.y, i.h] for i in INTRUDERS])
    vel = np.array([[i.vx, i.vy, i.vh] for i in INTRUDERS])
    goal = np.array(GOAL)
    values = np.empty((9, 9))
    for a in range(9):
        first = model.fly(
            ownship_state(OWN)[None], np.array([a]), goal, hold,
            model.predict(pos, vel, hold), cull=False, exact=True,
        )  # fmt: skip
        if first.event[0] != NONE:
            values[a] = TERMINAL_VALUE[first.event[0]]
            continue
        for b in range(9):
            second = model.fly(
                first.end, np.array([b]), goal, hold,
                model.predict(pos, vel, hold, t0=hold), cull=False, exact=True,
            )  # fmt: skip
            e = int(second.event[0])
            end = second.end[0, :3]
            leaf = 1.0 - math.dist(end, GOAL) / cfg.d_max
            values[a, b] = TERMINAL_VALUE[e] if e != NONE else leaf
    return values


def test_exhaustive_finds_the_best_sequence():
    cfg = PlannerConfig(depth=2, **PAPER)
    values = brute_force_values(cfg)
    assert values.min() == 0.0 and values.max() > 0.5  # some sequences collide, some not
    d = ExhaustivePlanner(cfg).plan(OWN, INTRUDERS, GOAL)
    q = np.array([c.q for c in d.children])
    np.testing.assert_allclose(q, values.max(axis=1), atol=1e-6)
    assert d.action == int(np.argmax(values.max(axis=1)))
    open_first = int(np.sum(d.tree.terminal[d.tree.children_of(0)] == NONE))
    assert (d.tree.depth == 2).sum() == 9 * open_first  # all 9 x 9 sequences, bar collisions
    assert d.confidence == 1.0


def test_exhaustive_tree_holds_every_sequence():
    cfg = PlannerConfig(depth=3)
    d = ExhaustivePlanner(cfg).plan(OWN, INTRUDERS, GOAL)
    tree = d.tree
    open_inner = (tree.depth < 3) & (tree.terminal == NONE)
    # every open node below the limit has its 9 children: nothing was sampled away
    for node in np.flatnonzero(open_inner):
        assert len(tree.children_of(node)) == 9
    assert (tree.depth == 1).sum() == 9


def test_mcts_never_picks_a_collision_when_exhaustive_sees_a_way_out():
    cfg = PlannerConfig(depth=2, simulations=300, **PAPER)
    values = brute_force_values(cfg).max(axis=1)
    assert np.any(values == 0.0) and np.any(values > 0.0)
    for seed in range(3):
        d = MCTSPlanner(PlannerConfig(depth=2, simulations=300, seed=seed, **PAPER)).plan(
            OWN, INTRUDERS, GOAL
        )
        assert values[d.action] > 0.0
        assert values[d.action] == pytest.approx(values.max(), abs=0.01)


def test_goal_sooner_breaks_ties_and_nothing_else():
    """Lines that reach the goal all score about 1; the sooner one must win, or re-planning
    can put the goal off for ever. The tie-break only orders goal lines among themselves."""
    cfg = PlannerConfig(depth=3)
    own = Ownship(1000.0, 1000.0, 120.0, 20.0, 0.0)  # 120 m short of the goal, heading at it
    goal = (1000.0, 1120.0, 120.0)
    d = ExhaustivePlanner(cfg).plan(own, [], goal)
    tree = d.tree
    reached = tree.terminal == GOAL_CODE
    assert reached.any() and (tree.depth[reached] > 1).any()
    q = {c.action: c.q for c in d.children}
    goal_first = {int(tree.action[n]) for n in tree.children_of(0) if tree.terminal[n] == GOAL_CODE}
    assert goal_first  # some actions reach it in the first level ...
    assert d.action in goal_first  # ... and one of them is taken
    later = [a for a in q if a not in goal_first and q[a] > 0.99]
    assert later  # and some reach it only in the second level
    assert all(q[a] < q[d.action] for a in later)  # reaching it later scores (a little) less
    assert all(q[a] > 1.0 - 1e-3 for a in later)  # ... but only a little
    assert q[d.action] == 1.0


def test_exhaustive_does_not_orbit_the_goal():
    """Seed 110 of the demo campaign with 5 intruders: before the tie-break the planner
    circled about 200 m from the goal until it timed out (400 decisions)."""
    from uavxai.scenario import default_scenario
    from uavxai.sim.build import run_kinematic as run_episode

    r = run_episode("exhaustive", default_scenario("demo"), 110, 5)
    assert r.outcome == "goal"
    assert r.steps < 100


def test_the_reference_values_lines_without_the_compiled_search_s_terms():
    """mcts_sep's NMAC cost and walls live in the compiled search only: the exhaustive
    reference's config says it values lines without them (and without the chance)."""
    import dataclasses

    from uavxai.avoidance.planners import sep_config

    sep = sep_config(PlannerConfig())
    assert sep.nmac_cost > 0 and sep.wall_slack_s > 0
    ref = ExhaustivePlanner(dataclasses.replace(sep, risk="probability")).config
    assert (ref.nmac_cost, ref.wall_slack_s, ref.risk) == (0.0, 0.0, "margin")
