"""Room to manoeuvre (PlannerConfig.clearance_buffer_m / clearance_value): an open leaf
whose line passes an intruder within d_min + buffer is worth less, by how far inside."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.avoidance.mcts import TreeBuilder, predict_levels
from uavxai.avoidance.model import EncounterModel
from uavxai.avoidance.types import Intruder, Ownship, PlannerConfig
from uavxai.errors import UserError
from uavxai.vocabulary import HOLD

# The ownship flies north at 20 m/s; one intruder flies beside it, 75 m east, at the same
# speed and height: holding the line passes it at 75 m all along (no margin: cv, exact track).
OWN = Ownship(x=500.0, y=500.0, h=120.0, speed=20.0, heading=0.0)
BESIDE = Intruder(id=1, x=575.0, y=500.0, h=120.0, vx=0.0, vy=20.0)
GOAL = np.array([500.0, 1500.0, 120.0])


def leaf_of_hold(**overrides) -> tuple[TreeBuilder, int]:
    cfg = PlannerConfig(
        actions="vertical", intruder_model="cv", uncertainty_k=0.0, depth=1, **overrides
    )
    model = EncounterModel(cfg)
    tracks = predict_levels(model, [BESIDE], cfg.depth, cfg.action_hold_s)
    root = np.array([OWN.x, OWN.y, OWN.h, OWN.speed, OWN.heading, 0.0, 0.0, 0.0])
    builder = TreeBuilder(model, root, GOAL, tracks, cfg.action_hold_s, math.inf)
    first = builder.expand(0)
    return builder, first + HOLD


def test_a_line_inside_the_buffer_is_worth_less_by_how_far_inside() -> None:
    plain, node = leaf_of_hold()
    roomy, node_r = leaf_of_hold(clearance_buffer_m=100.0, clearance_value=0.05)
    # 75 m from a 50 m d_min with a 100 m buffer: a quarter of the buffer left
    assert roomy.crowding(node_r) == pytest.approx(0.75, abs=0.01)
    assert plain.leaf_value(node) - roomy.leaf_value(node_r) == pytest.approx(0.0375, abs=5e-4)


def test_a_line_beyond_the_buffer_keeps_eq_13() -> None:
    plain, node = leaf_of_hold()
    roomy, node_r = leaf_of_hold(clearance_buffer_m=20.0, clearance_value=0.05)
    assert roomy.crowding(node_r) == 0.0
    assert roomy.leaf_value(node_r) == plain.leaf_value(node)


def test_off_by_default_and_bounded() -> None:
    cfg = PlannerConfig()
    assert cfg.clearance_value == 0.0 and cfg.cull_m == cfg.d_min_m
    assert PlannerConfig(clearance_buffer_m=80.0, clearance_value=0.02).cull_m == 130.0
    with pytest.raises(UserError):
        PlannerConfig(clearance_value=0.1)
    with pytest.raises(UserError):
        PlannerConfig(clearance_buffer_m=-1.0)
