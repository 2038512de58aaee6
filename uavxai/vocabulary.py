"""The words every layer shares, written once: the avoidance actions and the episode outcomes.

Planners, the encounter model, explanations, the tree graph, the recorder and the campaigns
all read the action table and the outcome enum from here, so an action is called the same
thing in a search tree, a sentence, a recording and a results table.

Actions (the paper's 9): index ``3 * bank_index + accel_index`` with bank (left, hold,
right) and acceleration (up, hold, down). A bank action moves the *bank command* one
``bank_step_deg`` step (hold keeps the current command, which may be a turn); an
acceleration action commands ``accel_mps2`` along the track. These fly the height the
autopilot holds for the leg (the goal's).

Beyond the paper, two vertical actions follow them (indices 9 and 10), holding the bank
command and the speed: climb and descend step a *vertical command* one place along
(descend, the leg's height, climb), as bank actions step the bank command, and the nine keep
it, as hold keeps a turn. Climbing, the autopilot's height target is the flight area's
ceiling less a margin and it climbs at its climb-rate limit until it levels off there
(descending likewise to the floor); at the leg's height it flies the goal's height, as the
paper's nine always do. One climb therefore starts a climb that lasts while the search adds
bank and speed actions, and one descend from a climb returns to the leg's height. An
*action set* is a prefix of the table (:data:`ACTION_SETS`): ``paper`` the first 9,
``vertical`` all 11. Two actions rather than the 27 products of bank x acceleration x
vertical: a tree search's cost grows with its branching, and at a fixed simulation budget 27
children would leave each root action a third of the simulations it has with 9 (a depth-4
exhaustive tree would grow from 7,381 to 551,881 nodes); 11 cost about a fifth more, and
because the vertical command persists, a climb combined with any bank or speed change is
one climb followed by that action.
"""

from __future__ import annotations

import re
from dataclasses import dataclass
from enum import StrEnum
from functools import cache


@dataclass(frozen=True)
class Action:
    index: int
    bank: int  # -1 left, 0 hold the bank command, +1 right (steps of bank_step_deg)
    accel: int  # +1 speed up, 0 hold speed, -1 slow down (times accel_mps2)
    short: str  # tree-graph label, e.g. "left/faster"
    name: str  # "bank left, speed up"
    phrase: str  # how an explanation names the option: "left and faster", "holding bank and speed"
    verb: str  # what the aircraft did: "banked left and sped up"
    # +1 climb, -1 descend: the step it gives the vertical command; 0 keeps it (the nine)
    climb: int = 0


_BANK = (
    (-1, "left", "bank left", "banked left"),
    (0, "hold", "hold bank", "held its bank"),
    (+1, "right", "bank right", "banked right"),
)
_ACCEL = (
    (+1, "faster", "speed up", " and faster", " and sped up"),
    (0, "same", "hold speed", "", ""),
    (-1, "slower", "slow down", " and slower", " and slowed down"),
)


def _table() -> tuple[Action, ...]:
    out = []
    for b, (bank, b_short, b_name, b_verb) in enumerate(_BANK):
        for c, (accel, a_short, a_name, a_phrase, a_verb) in enumerate(_ACCEL):
            phrase = {-1: "left", 0: "holding", 1: "right"}[bank] + a_phrase
            if bank == 0 and accel == 0:
                phrase = "holding bank and speed"
            out.append(
                Action(
                    index=3 * b + c,
                    bank=bank,
                    accel=accel,
                    short=f"{b_short}/{a_short}",
                    name=f"{b_name}, {a_name}",
                    phrase=phrase,
                    verb=b_verb + a_verb,
                )
            )
    for climb, short, name, phrase, verb in _VERTICAL:
        out.append(Action(len(out), 0, 0, short, name, phrase, verb, climb))
    return tuple(out)


_VERTICAL = (
    (+1, "climb", "climb, hold bank and speed", "climbing", "climbed"),
    (-1, "descend", "descend, hold bank and speed", "descending", "descended"),
)
ACTIONS: tuple[Action, ...] = _table()
# Action sets: how many of the table's first actions each offers (`avoidance.actions`).
ACTION_SETS = {"paper": 9, "vertical": len(ACTIONS)}
# A tree planner's conflict volume around each intruder (`avoidance.conflict_volume`).
CONFLICT_VOLUMES = ("sphere", "cylinder")
# How a tree planner counts a track's uncertainty (`avoidance.mcts.risk`): "margin", k sigmas
# of it as a wall; "probability", the chance of losing separation, in the line's value.
RISK_MODELS = ("margin", "probability")
# What an MCTS node's Q is (`avoidance.mcts.backup`): "mean", the mean value of the walks
# through it, the most visited root action taken (the paper); "best", the best value a walk
# through it scored, the root action with the best Q taken (as the exhaustive search does).
BACKUPS = ("mean", "best")
# How a tree planner picks when every option's line conflicts (`avoidance.mcts.cornered_rule`,
# uavxai.avoidance.lines.cornered_key): "latest", the latest meeting, then the widest miss of
# the intruder met; "widest", the widest predicted closest approach to any intruder (up to
# twice the collision distance), then the latest meeting.
CORNERED_RULES = ("latest", "widest")
N_ACTIONS = ACTION_SETS["paper"]  # the paper's nine: the learned planners' output size
HOLD = 4  # hold the bank command, hold speed: the reference every other option is compared to
CLIMB, DESCEND = (next(a.index for a in ACTIONS if a.climb == c) for c in (+1, -1))
BANK_SIGNS = tuple(a.bank for a in ACTIONS[:N_ACTIONS:3])  # (-1, 0, +1) by bank index
ACCEL_SIGNS = tuple(a.accel for a in ACTIONS[:3])  # (+1, 0, -1) by accel index
assert ACTIONS[HOLD].bank == 0 and ACTIONS[HOLD].accel == 0
assert all(a.climb == 0 for a in ACTIONS[:N_ACTIONS])


def action_name(a: int) -> str:
    """'bank left, speed up' for action index ``a``."""
    return ACTIONS[a].name


# Planner names: the scenario schema validates against these; the registries
# (uavxai.avoidance.planners, uavxai.service.stage) provide one factory for each and check at
# import that they cover exactly these names, so a name is written once.
AVOIDANCE_PLANNERS = (
    "mcts", "mcts_fast", "exhaustive", "mcts_vertical", "mcts_daa", "mcts_route", "mcts_sep",
    "mcts_sep_daa", "mvp", "dqn", "safe_dqn", "none",
)  # fmt: skip
# The planners that fly the vertical action set: the tree searches (mcts_vertical always
# does) and `none`, which flies straight to the goal whatever the set. mvp resolves in the
# horizontal plane and dqn / safe_dqn were trained on the paper's nine: they refuse it.
VERTICAL_PLANNERS = ("mcts", "mcts_fast", "exhaustive", "mcts_vertical", "mcts_daa", "mcts_route",
                     "mcts_sep", "mcts_sep_daa", "none")  # fmt: skip
# Avoidance planners other packages install: an entry point in this group names a factory
# ``(config: PlannerConfig, checkpoint) -> Planner`` (README, "Your own planner"). Their
# names are read from the packages' metadata, without importing them, so that the schema can
# check a scenario cheaply; a plugin flies the paper's nine.
PLANNER_ENTRY_POINTS = "uavxai.planners"
_PLUGIN_NAME = re.compile(r"[a-z][a-z0-9_]{0,39}")


@cache  # read once per process (10 ms a scan): packages are installed between runs
def plugin_planners() -> tuple[str, ...]:
    """The installed plugins' planner names (group :data:`PLANNER_ENTRY_POINTS`), sorted: those
    that are lower-case slugs of at most 40 characters and not a built-in planner's name (the
    built-in keeps it)."""
    from importlib.metadata import entry_points

    names = {ep.name for ep in entry_points(group=PLANNER_ENTRY_POINTS)}
    return tuple(sorted(n for n in names
                        if _PLUGIN_NAME.fullmatch(n) and n not in AVOIDANCE_PLANNERS))  # fmt: skip


def avoidance_planners() -> tuple[str, ...]:
    """Every avoidance planner a scenario, `--methods` or a campaign may name: the built-in
    ones, then the installed plugins'."""
    return AVOIDANCE_PLANNERS + plugin_planners()
SERVICE_PLANNERS = ("d3qn", "dqn", "random", "grid")


def action_set_problem(planner: str, actions: str) -> str | None:
    """Why ``planner`` cannot fly the action set ``actions`` (None: it can). The one rule the
    scenario schema and the planner factory both apply."""
    if actions == "paper" or planner in VERTICAL_PLANNERS:
        return None
    return (
        f"avoidance.actions: {actions} is flown by {', '.join(VERTICAL_PLANNERS)}; planner "
        f"'{planner}' flies only the paper set (mvp resolves in the horizontal plane, dqn and "
        "safe_dqn were trained on the nine, a plugin flies the nine). Use avoidance.actions: "
        "paper with it."
    )


@dataclass(frozen=True)
class ChannelValidity:
    """Where a standard air-to-ground channel model holds (3GPP TR 36.777 V15.0.0 Tables
    B-1 and B-2): aerial heights ``h_min_m < h <= h_max_m`` above the ground node and
    horizontal distances ``d2D <= d2d_max_m``. The scenario refuses a flight area that leaves
    it (uavxai.scenario.Scenario); the formulas are uavxai.comms.pathloss."""

    standard: str
    h_min_m: float  # exclusive, as the standard writes "22.5 m < h_UT"
    h_max_m: float  # inclusive
    d2d_max_m: float


# The air-to-ground channel models a scenario can select (`comms.channel`), by name. The
# paper's Al-Hourani fit has no such range (None): it is a function of the elevation angle only.
CHANNEL_MODELS: dict[str, ChannelValidity | None] = {
    "al_hourani": None,
    "uma_av": ChannelValidity("3GPP TR 36.777 UMa-AV", 22.5, 300.0, 4_000.0),
    "umi_av": ChannelValidity("3GPP TR 36.777 UMi-AV", 22.5, 300.0, 4_000.0),
    "rma_av": ChannelValidity("3GPP TR 36.777 RMa-AV", 10.0, 300.0, 10_000.0),
}
CHANNEL_MODEL_NAMES = tuple(CHANNEL_MODELS)
# The worlds a campaign flies in (`uavxai evaluate --dynamics`; uavxai.sim.build.DYNAMICS
# builds them): named here so that the command line need not import JSBSim's side to list them.
DYNAMICS_MODELS = ("jsbsim", "kinematic")


class Outcome(StrEnum):
    """How an episode ends (README, "What a run produces"). The
    values are what files and tables say."""

    GOAL = "goal"  # a transit-only episode reached its goal
    COMPLETED = "completed"  # a mission flown to its end
    COLLISION = "collision"  # 3-D separation below d_min at any instant
    TIMEOUT = "timeout"  # max_steps decisions without any other end
    OUT_OF_BOUNDS = "out_of_bounds"  # the ownship left the flight area
    BATTERY = "battery"  # the battery reached its reserve away from home
    FDM_FAILURE = "fdm_failure"  # the flight dynamics gave up (NaN, ground strike, envelope)
    INTERRUPTED = "interrupted"  # stopped by a signal; the files are whole but the run is partial


OUTCOMES = tuple(o.value for o in Outcome)
