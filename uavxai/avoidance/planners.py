"""Avoidance planners by name: the factory behind `avoidance.planner`, `uavxai evaluate
--methods` and the pipeline. The built-in ones are registered here; other packages add theirs
through the entry-point group ``uavxai.planners`` (README, "Your own planner"), loaded when
first asked for.

Every planner follows :class:`uavxai.avoidance.types.Planner`: ``plan(own, intruders, goal,
*, step) -> Decision`` and ``reset(seed)``, with ``name`` and ``config`` attributes. The
learned ones (``dqn``, ``safe_dqn``) live in :mod:`uavxai.avoidance.learned`, imported only
when asked for (it needs torch), through ``make_learned_planner(name, config, checkpoint)``.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Callable
from pathlib import Path

from uavxai.avoidance import direct
from uavxai.avoidance.alerting import AlertingPlanner
from uavxai.avoidance.direct import DirectPlanner
from uavxai.avoidance.exhaustive import ExhaustivePlanner
from uavxai.avoidance.mcts import MCTSPlanner
from uavxai.avoidance.mvp import MVPPlanner
from uavxai.avoidance.route import RoutedPlanner
from uavxai.avoidance.types import Planner, PlannerConfig
from uavxai.errors import UserError
from uavxai.vocabulary import (
    AVOIDANCE_PLANNERS,
    PLANNER_ENTRY_POINTS,
    action_set_problem,
    avoidance_planners,
    plugin_planners,
)

# The paper's Tree-fast: few simulations, a shallow tree, short holds.
TREE_FAST = {"simulations": 40, "depth": 2, "action_hold_s": 2.0}

PlannerFactory = Callable[[PlannerConfig, "str | Path | None"], Planner]
# Every avoidance planner by name: the scenario schema, `uavxai evaluate --methods` and the
# campaigns read their choices from here.
PLANNERS: dict[str, PlannerFactory] = {}
LEARNED = ("dqn", "safe_dqn")


def register(name: str) -> Callable[[PlannerFactory], PlannerFactory]:
    """Register a planner factory ``(config, checkpoint) -> Planner`` under ``name``."""

    def add(factory: PlannerFactory) -> PlannerFactory:
        PLANNERS[name] = factory
        return factory

    return add


def fast_config(config: PlannerConfig) -> PlannerConfig:
    """``config`` with the Tree-fast search settings."""
    return dataclasses.replace(config, **TREE_FAST)


register("mcts")(lambda config, checkpoint: MCTSPlanner(config))
register("mcts_fast")(lambda config, checkpoint: MCTSPlanner(fast_config(config), name="mcts_fast"))
register("exhaustive")(lambda config, checkpoint: ExhaustivePlanner(config))
# MCTS over the vertical action set whatever `avoidance.actions` says: compared beside `mcts`
# in one campaign (`--methods mcts,mcts_vertical`).
register("mcts_vertical")(
    lambda config, checkpoint: MCTSPlanner(
        dataclasses.replace(config, actions="vertical"), name="mcts_vertical"
    )
)


# mcts_vertical behind an alerting stage: it searches only while traffic threatens well clear,
# for lines clear of the NMAC cylinder, and leaves its route only when the route's line
# conflicts. With the sphere (the default conflict volume) the smallest that holds the
# cylinder reaches its rim (152.4 m out, 30.48 m up: 155.4 m). A sphere of the cylinder's
# radius alone let a line pass at 150 m and 30 m, inside the NMAC (kinematic encounter 1264).
# With `avoidance.conflict_volume: cylinder` the tree's volume is the smallest cylinder that
# holds both the NMAC cylinder and the collision sphere (d_min_m): 152.4 m by
# max(30.48, d_min_m) up and down, not the 155 m a sphere fences off above and below.
def _daa_config(config: PlannerConfig) -> PlannerConfig:
    h, v = config.nmac_m
    # Its conflict volume holds the NMAC cylinder, so there is no NMAC volume left to grade:
    # avoidance.mcts.nmac_cost does not apply (with it the d_min check refused the planner).
    # Nor does avoidance.mcts.wall_slack_s: its alerting stage hands the ownship back to its
    # route within seconds of a threat, and its judged figures (docs/results) are without
    # walls; walls in its tree would be a new planner, to be judged as one. So too the
    # best-value backup (avoidance.mcts.backup): its campaigns were flown with the mean, and
    # the paper's goal distance (avoidance.mcts.goal_height_scale), with no pinning weighed
    # (avoidance.mcts.pinned_slack_s), the goal's whole sphere (avoidance.mcts.goal_margin_m)
    # and the cornered rule it was judged with (avoidance.mcts.cornered_rule).
    config = dataclasses.replace(
        config, nmac_cost=0.0, wall_slack_s=0.0, backup="mean", goal_height_scale=1.0,
        pinned_slack_s=0.0, goal_margin_m=0.0, cornered_rule="latest",
    )
    if config.conflict_volume == "cylinder":
        return dataclasses.replace(
            config,
            actions="vertical",
            d_min_m=max(config.d_min_m, h),
            conflict_half_height_m=max(config.d_min_m, v),
        )
    return dataclasses.replace(
        config, actions="vertical", d_min_m=max(config.d_min_m, math.hypot(h, v))
    )


register("mcts_daa")(
    lambda config, checkpoint: AlertingPlanner(
        MCTSPlanner(_daa_config(config), name="mcts_daa"), name="mcts_daa"
    )
)
# Issue 27's multi-threat goal while arriving (docs/results "Safe among many and still
# arriving"): mcts_vertical (the hard conflict at the collision distance d_min_m) whose values
# grade NMAC intrusion as a cost instead of a wall (nmac_cost) and whose leaves and late
# collisions know whether they can still turn away from the walls (wall_slack_s). Not
# mcts_daa's home: that one's alerting stage and 155 m wall are what make it leave the area.
SEPARATION = {"nmac_cost": 0.5, "wall_slack_s": 4.0}


def sep_config(config: PlannerConfig) -> PlannerConfig:
    """``config`` as `mcts_sep` flies it: the vertical set, graded separation, walls."""
    return dataclasses.replace(config, actions="vertical", **SEPARATION)


register("mcts_sep")(lambda config, checkpoint: MCTSPlanner(sep_config(config), name="mcts_sep"))
# Issue 27's two tables with one planner: mcts_sep's tree (its values, its 50 m hard conflict)
# behind mcts_daa's alerting stage, so that it flies the route (as `none`) until traffic
# threatens well clear and leaves the route only when the route's own line conflicts.
register("mcts_sep_daa")(
    lambda config, checkpoint: AlertingPlanner(
        MCTSPlanner(sep_config(config), name="mcts_sep_daa"), name="mcts_sep_daa"
    )
)
register("mvp")(lambda config, checkpoint: MVPPlanner(config))
# mcts_vertical steering for a coarse route's waypoint (uavxai.avoidance.route): issue 31's
# route layer, so that the tree is not lured between intruders into a dead end.
register("mcts_route")(
    lambda config, checkpoint: RoutedPlanner(
        MCTSPlanner(dataclasses.replace(config, actions="vertical"), name="mcts_route"),
        name="mcts_route",
    )
)


def _learned(name: str) -> PlannerFactory:
    def make(config: PlannerConfig, checkpoint: str | Path | None) -> Planner:
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

    return make


for _name in LEARNED:
    register(_name)(_learned(_name))
register(direct.NAME)(lambda config, checkpoint: DirectPlanner(config))


def uses_compiled_search(planner: Planner) -> bool:
    """Does ``planner`` search with the compiled MCTS kernel, itself or through the tree it
    wraps (`mcts_daa`'s alerting stage, `mcts_route`'s route layer)? Its first decision in a
    process loads the kernel (uavxai.sim.companion.warm_up)."""
    if isinstance(planner, AlertingPlanner | RoutedPlanner):
        planner = planner.inner
    return isinstance(planner, MCTSPlanner)


def make_planner(
    name: str, config: PlannerConfig | None = None, checkpoint: str | Path | None = None
) -> Planner:
    """The planner called ``name`` (a key of PLANNERS) with ``config``; ``checkpoint`` is the
    model.pt of a learned planner (None: the shipped one) and is ignored by the others."""
    factory = PLANNERS.get(name) or _plugin(name)
    if factory is None:
        raise UserError(
            f"unknown avoidance planner '{name}'; choose one of {', '.join(avoidance_planners())}."
        )
    config = config or PlannerConfig()
    check_action_set(name, config.actions)
    planner = factory(config, checkpoint)
    if name not in PLANNERS and not isinstance(planner, Planner):
        raise UserError(
            f"avoidance planner '{name}' (a plugin) returned a {type(planner).__name__!r} "
            "object, not a planner: a planner needs plan(own, intruders, goal, *, step) -> "
            "Decision, reset(seed), name and config (README, planner API)."
        )
    return planner


def _plugin(name: str) -> PlannerFactory | None:
    """The factory an installed package registers for ``name`` (entry point group
    :data:`PLANNER_ENTRY_POINTS`), loaded (its module imported) only now that it is asked for;
    None if no plugin has that name."""
    if name not in plugin_planners():
        return None
    from importlib.metadata import entry_points

    ep = next(iter(entry_points(group=PLANNER_ENTRY_POINTS, name=name)))
    try:
        factory = ep.load()
    except Exception as exc:  # its code, not ours: say whose and go no further
        raise UserError(
            f"avoidance planner '{name}' (entry point {ep.value} of group "
            f"{PLANNER_ENTRY_POINTS}) could not be loaded: {type(exc).__name__}: {exc}"
        ) from None
    if not callable(factory):
        raise UserError(
            f"avoidance planner '{name}': entry point {ep.value} is not a factory "
            "(config, checkpoint) -> Planner."
        )
    return factory


def check_action_set(planner: str, actions: str) -> None:
    """A UserError if ``planner`` cannot fly the action set ``actions``."""
    problem = action_set_problem(planner, actions)
    if problem:
        raise UserError(problem)


# The registry provides every planner the vocabulary names, and nothing else.
assert tuple(sorted(PLANNERS)) == tuple(sorted(AVOIDANCE_PLANNERS)), sorted(PLANNERS)
