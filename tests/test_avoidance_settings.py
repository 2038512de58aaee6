"""Every planner setting the scenario declares reaches the planner, from the schema alone
(issue 29: a new `avoidance` key is a schema edit and the planner code that reads it)."""

from __future__ import annotations

import dataclasses
from typing import Any

import pytest
from pydantic import BaseModel

from uavxai.avoidance import PlannerConfig
from uavxai.avoidance.settings import ENGINE_KEYS
from uavxai.errors import UserError
from uavxai.scenario import Avoidance, default_scenario

# A valid value other than the default for every planner setting of the scenario (one
# scenario holds them all, so they agree with each other: the bank step within the limit, the
# decision period on the clock, the speeds within uav_fw's).
NON_DEFAULT: dict[str, Any] = {
    "world.x": [0.0, 2500.0],
    "world.y": [-100.0, 2000.0],
    "world.h": [40.0, 320.0],
    "avoidance.d_min_m": 60.0,
    "avoidance.goal_radius_m": 40.0,
    "avoidance.decision_period_s": 2.0,
    "avoidance.max_steps": 300,
    "avoidance.bank_limit_deg": 35.0,
    "avoidance.bank_step_deg": 5.0,
    "avoidance.accel_mps2": 1.5,
    "avoidance.speed_mps": [14.0, 28.0],
    "avoidance.actions": "vertical",
    "avoidance.conflict_volume": "cylinder",
    "avoidance.mcts.simulations": 120,
    "avoidance.mcts.depth": 3,
    "avoidance.mcts.c": 1.5,
    "avoidance.mcts.action_hold_s": 3.0,
    "avoidance.mcts.reach_horizon_s": 2.0,
    "avoidance.mcts.intruder_bank_limit_deg": 45.0,
    "avoidance.mcts.own_error_10s_m": 5.0,
    "avoidance.mcts.uncertainty_horizon_s": 8.0,
    "avoidance.mcts.uncertainty_k": 3.0,
    "avoidance.mcts.nmac_cost": 0.3,
    "avoidance.mcts.backup": "best",
    "avoidance.mcts.wall_slack_s": 3.0,
    "avoidance.mcts.goal_height_scale": 8.0,
    "avoidance.mcts.pinned_slack_s": 3.0,
    "avoidance.mcts.goal_margin_m": 10.0,
    "avoidance.mcts.cornered_rule": "widest",
    "avoidance.nmac.horizontal_m": 100.0,
    "avoidance.nmac.vertical_m": 20.0,
    "avoidance.well_clear.horizontal_m": 500.0,
    "avoidance.well_clear.vertical_m": 60.0,
}
# Keys whose non-default value another non-default refuses (probability needs the sphere),
# checked together in a scenario of their own (the risk wall needs the probability).
ALONE = {"avoidance.mcts.risk": "probability", "avoidance.mcts.risk_wall_s": 4.0}
# A vertical margin of its own needs the sphere and the margin: a scenario of its own too.
ALONE_VERTICAL = {"avoidance.mcts.vertical_reach_mps": 2.5}
# Where the planner reads the keys it names otherwise: (PlannerConfig field, index in its pair).
RENAMED = {
    "world.x": ("x_bounds", None),
    "world.y": ("y_bounds", None),
    "world.h": ("h_bounds", None),
    "avoidance.nmac.horizontal_m": ("nmac_m", 0),
    "avoidance.nmac.vertical_m": ("nmac_m", 1),
    "avoidance.well_clear.horizontal_m": ("alert_well_clear_m", 0),
    "avoidance.well_clear.vertical_m": ("alert_well_clear_m", 1),
}


def _leaves(model: type[BaseModel], prefix: str) -> list[str]:
    """Every key of ``model`` and of its sub-sections, dotted."""
    out = []
    for key, info in model.model_fields.items():
        ann = info.annotation
        if isinstance(ann, type) and issubclass(ann, BaseModel):
            out += _leaves(ann, f"{prefix}.{key}")
        else:
            out.append(f"{prefix}.{key}")
    return out


def _nested(flat: dict[str, Any]) -> dict[str, Any]:
    out: dict[str, Any] = {}
    for dotted, value in flat.items():
        *parents, key = dotted.split(".")
        node = out
        for p in parents:
            node = node.setdefault(p, {})
        node[key] = value
    return out


def _read(cfg: PlannerConfig, dotted: str) -> Any:
    name, index = RENAMED.get(dotted, (dotted.rsplit(".", 1)[-1], None))
    value = getattr(cfg, name)
    return value if index is None else value[index]


def test_every_avoidance_key_reaches_the_planner_config():
    # the keys kept from the planner: which planner, its weights, the engine's latency
    assert set(ENGINE_KEYS) == {"planner", "checkpoint", "decision_latency_s"}
    keys = [k for k in _leaves(Avoidance, "avoidance")
            if k.removeprefix("avoidance.") not in ENGINE_KEYS]  # fmt: skip
    missing = sorted(set(keys) - set(NON_DEFAULT) - set(ALONE) - set(ALONE_VERTICAL))
    assert missing == [], f"give {missing} a non-default value in NON_DEFAULT"
    default = PlannerConfig.from_scenario(default_scenario())
    cfg = PlannerConfig.from_scenario(default_scenario(**_nested(NON_DEFAULT)))
    for dotted, value in NON_DEFAULT.items():
        expected = tuple(value) if isinstance(value, list) else value
        assert _read(cfg, dotted) == expected, dotted
        assert _read(default, dotted) != expected, dotted
    for alone in (ALONE, ALONE_VERTICAL):
        cfg = PlannerConfig.from_scenario(default_scenario(**_nested(alone)))
        for dotted, value in alone.items():
            assert _read(cfg, dotted) == value != _read(default, dotted), dotted


def test_the_new_key_reaches_the_search():
    """avoidance.mcts.uncertainty_k (issue 31's margin), exposed by a schema edit alone."""
    sc = default_scenario(avoidance={"mcts": {"uncertainty_k": 0.5}})
    assert PlannerConfig.from_scenario(sc).uncertainty_k == 0.5
    assert PlannerConfig().uncertainty_k == 2.0  # the schema's default
    with pytest.raises(UserError, match=r"avoidance\.mcts\.uncertainty_k' = 11: Input should be"):
        default_scenario(avoidance={"mcts": {"uncertainty_k": 11}})


@pytest.mark.parametrize(
    ("overrides", "message"),
    [
        ({"depth": 9}, r"'PlannerConfig\.depth' = 9: Input should be less than or equal to 8"),
        ({"nmac_m": (152.4, -1.0)}, r"'PlannerConfig\.nmac_m' = -1\.0: .* greater than 0"),
        ({"h_bounds": (0.0, 300.0)}, r"'PlannerConfig\.h_bounds' .* above the ground"),
        ({"bank_step_deg": 40.0}, r"PlannerConfig: bank_step_deg \(40\.0\) must not exceed"),
        ({"substep_s": 0.0}, r"PlannerConfig\.substep_s must be > 0"),  # the planner's own
    ],
)
def test_a_bad_override_names_the_field_and_what_is_allowed(overrides, message):
    with pytest.raises(UserError, match=message):
        PlannerConfig.from_scenario(default_scenario(), **overrides)
    with pytest.raises(UserError, match=message):
        dataclasses.replace(PlannerConfig(), **overrides)


def test_values_are_kept_as_the_schema_keeps_them():
    cfg = PlannerConfig(x_bounds=[0, 900], d_min_m=60, speed_mps=[14, 28])
    assert cfg.x_bounds == (0.0, 900.0) and isinstance(cfg.x_bounds[1], float)
    assert (cfg.d_min_m, cfg.speed_mps) == (60.0, (14.0, 28.0))
    assert hash(cfg) == hash(dataclasses.replace(cfg))  # frozen, hashable as before


def test_nmac_cost_is_refused_where_no_planner_could_fly_it_and_mcts_daa_ignores_it():
    """avoidance.mcts.nmac_cost above 0.5 would let a late collision outrank a time-out through
    the NMAC volume, which PlannerConfig refuses by a field the user cannot set: the schema
    refuses it by the key's name instead. `mcts_daa`'s conflict volume holds the NMAC cylinder,
    so the key does not apply to it (before, any value refused the planner)."""
    from uavxai.avoidance.planners import make_planner

    with pytest.raises(UserError, match=r"avoidance\.mcts\.nmac_cost' = 0\.7: Input should be"):
        default_scenario(avoidance={"mcts": {"nmac_cost": 0.7}})
    cfg = PlannerConfig.from_scenario(default_scenario(avoidance={"mcts": {"nmac_cost": 0.5}}))
    assert cfg.nmac_cost == 0.5
    daa = make_planner("mcts_daa", cfg)
    assert daa.config.nmac_cost == 0.0 and daa.config.d_min_m > cfg.nmac_m[0]


def test_wall_slack_is_a_scenario_key_refused_by_name_and_mcts_daa_ignores_it():
    """avoidance.mcts.wall_slack_s (issue 32's fleet mission: `mcts` members that keep off the
    world's edges) reaches `mcts`, is refused by its name outside 0 ... 60 s, and changes
    neither `mcts_sep` (which flies 4 s whatever is set) nor `mcts_daa` (which ignores it)."""
    from uavxai.avoidance.planners import make_planner

    for bad in (-1, 61):
        with pytest.raises(UserError, match=r"avoidance\.mcts\.wall_slack_s' = "):
            default_scenario(avoidance={"mcts": {"wall_slack_s": bad}})
    assert PlannerConfig.from_scenario(default_scenario()).wall_slack_s == 0.0
    cfg = PlannerConfig.from_scenario(default_scenario(avoidance={"mcts": {"wall_slack_s": 9}}))
    assert make_planner("mcts", cfg).config.wall_slack_s == 9.0
    assert make_planner("mcts_sep", cfg).config.wall_slack_s == 4.0
    assert make_planner("mcts_daa", cfg).config.wall_slack_s == 0.0
