"""Planner API types (README, "Using the planner in another simulator"): what goes into a
planner and what comes out.

These are plain data so that a planner works without JSBSim, MAVLink or rerun. Headings are
radians clockwise from north (aviation convention); positions ENU metres.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import asdict, dataclass, field, replace
from typing import TYPE_CHECKING, Protocol, runtime_checkable

import numpy as np

from uavxai.avoidance.settings import (
    SCHEMA_PATHS,
    SchemaSettings,
    check_schema_settings,
    schema_settings,
)
from uavxai.errors import UserError
from uavxai.vocabulary import ACTION_SETS, N_ACTIONS, action_name

if TYPE_CHECKING:
    from uavxai.scenario import Scenario


@dataclass(frozen=True)
class Ownship:
    x: float
    y: float
    h: float
    speed: float  # m/s along the track
    heading: float  # rad, clockwise from north
    bank: float = 0.0  # rad, right wing down positive (the current bank command)
    phi: float | None = None  # rad, the actual bank angle; None: settled at the command
    # The current vertical command (vertical action set): +1 climbing, -1 descending, 0 at
    # the leg's height (PlannerConfig.vertical_of reads it off the autopilot's height target)
    vertical: int = 0
    # The ground velocity (east, north) m/s as the ownship's navigation measures it. Less the
    # air velocity (speed along heading) it is the motion of the air it flies in: the steady
    # wind plus the gust of the moment (see uavxai.avoidance.model.ownship_air). None: not
    # known, the planner's steady wind only.
    ground_velocity: tuple[float, float] | None = None
    # The airspeeds the planner may fly (min, max); None: PlannerConfig.speed_mps. An
    # operator's DO_CHANGE_SPEED makes that speed the top (uavxai.sim.operator): the autopilot
    # flies no faster, and avoidance may still slow down to let traffic pass.
    speed_band: tuple[float, float] | None = None


@dataclass(frozen=True)
class Intruder:
    id: int | str
    x: float
    y: float
    h: float
    vx: float  # east, m/s
    vy: float  # north, m/s
    vh: float = 0.0  # up, m/s
    turn_rate: float = 0.0  # rad/s, + turning right (clockwise), as estimated
    sigma_m: float = 0.0  # 1-sigma horizontal position uncertainty, m
    sigma_v: float = 0.0  # 1-sigma velocity uncertainty, m/s
    age_s: float = 0.0  # age of the report the estimate rests on, s
    # separation to keep beyond d_min from it, m: a fleet member's cooperative clearance
    # (uavxai.sim.fleet.IntentPicture, docs/fleet.md); 0 for traffic
    keep_m: float = 0.0
    # the bank limit it may turn at, deg: its own performance (issue 31; the tracker gives it
    # by the ADS-B emitter category, uavxai.surveillance.emitters); None: the planner's
    # PlannerConfig.intruder_bank_limit_deg (the scenario's avoidance.mcts one)
    bank_limit_deg: float | None = None
    # 1-sigma vertical position (m) and vertical velocity (m/s) errors of the track (the
    # tracker's); None: not known, taken as the horizontal ones (avoidance.mcts.
    # vertical_reach_mps: a vertical margin of its own)
    sigma_h_m: float | None = None
    sigma_vh: float | None = None


INTRUDER_MODELS = ("cv", "ct", "reachable")

# The uav_fw autopilot's speed priority (ap/climb-rate-max-mps: 2 x (airspeed - (minimum
# speed - 1 m/s)), clipped to the climb-rate limit 2.5 m/s): no climb demanded 1 m/s below its
# minimum speed, the full rate 0.25 m/s above it; relative to the minimum speed.
CLIMB_SPEED_BAND_MPS = (-1.0, 0.25)


def climb_speed_band(gust_sigma_mps: float) -> tuple[float, float]:
    """The speeds (relative to the minimum) between which the ownship's climb rate grows from
    0 to the limit, in air whose gusts along the path have intensity ``gust_sigma_mps``: the
    autopilot reads its speed priority off the airspeed of the moment, which the gusts swing
    by that sigma, so its full rate is sure only one sigma above its band (measured, a lone
    uav_fw in moderate turbulence, climb of 4 s / 8 s at speed targets 12 and 13 m/s: median
    3.4 / 7.1 m and 6.8 / 15.6 m against 4.5 / 12.1 and 7.9 / 18.5 m in calm air;
    benchmarks/studies/bench_climb.py)."""
    lo, hi = CLIMB_SPEED_BAND_MPS
    return lo, hi + gust_sigma_mps


@dataclass(frozen=True)
class PlannerConfig(SchemaSettings):  # type: ignore[misc,valid-type]
    """The planner's settings. Those the scenario declares (every key of its `avoidance`
    section and of `avoidance.mcts` by the same name, the world's bounds as ``x_bounds``,
    ``y_bounds``, ``h_bounds``, the cylinders as ``nmac_m``, ``alert_well_clear_m``) are
    the fields of :data:`uavxai.avoidance.settings.SchemaSettings`, taken from the schema with
    its defaults and checked by its models (docs/scenario.md says what each is); the fields
    below are the planner's own, each with its check in ``__post_init__``."""

    # The ownship autopilot's limits: from_scenario reads them from its aircraft's XML.
    roll_rate_limit_deg_s: float = 30.0
    # The JSBSim autopilot holds the altitude target it is given (the goal's altitude) and
    # climbs or descends towards it no faster than this (its XML's, as the roll rate).
    climb_rate_mps: float = 2.5
    # Speed before height, as the autopilot flies it (ap/climb-rate-max-mps in
    # aircraft/uav_fw/Systems/uav_fw_autopilot.xml): it demands no climb at airspeeds below
    # speed_mps[0] + climb_speed_band_mps[0], the full climb rate from speed_mps[0] +
    # climb_speed_band_mps[1], linearly between; the model climbs no faster at its speed.
    # Sinking is not limited by speed. from_scenario raises the top of the band in turbulent
    # air, where the airspeed the autopilot reads swings with the gusts (climb_speed_band).
    climb_speed_band_mps: tuple[float, float] = CLIMB_SPEED_BAND_MPS
    # Longest sub-step of the encounter model. Collision checks are exact along each
    # sub-step's chord, so this only bounds how far the chord strays from the true arc
    # (at 20 m/s and 30 deg bank, 0.5 s gives 0.2 m).
    substep_s: float = 0.5
    seed: int = 0
    # How the planner predicts intruders (see uavxai.avoidance.model.intruder_margin):
    # "cv" constant velocity (the paper), "ct" a constant turn at the estimated turn rate,
    # "reachable" that turn, with the separation needed grown by how far the intruder could
    # stray from it within reach_horizon_s by banking anywhere within its bank limit (its own,
    # Intruder.bank_limit_deg, or the schema's intruder_bank_limit_deg).
    intruder_model: str = "reachable"
    # Value of a line that collides at the end of the search horizon (linear from 0 at once):
    # when every line meets someone, the search still prefers the one that meets them later,
    # which re-planning can still turn into a miss. 0: every collision is worth 0 (the paper).
    late_collision_value: float = 0.05
    # The steady wind the planner knows (east, north), m/s, that carries the air mass: the
    # model flies airspeed and heading through it, so its paths are over the ground, where
    # the intruders' tracks are (scenario `environment.wind`).
    wind_mps: tuple[float, float] = (0.0, 0.0)
    # Whether the air is turbulent (scenario `environment.turbulence` not "none"): then the
    # model also carries the ownship with the gust it measures (avoidance.model.ownship_air).
    # In steady air the measured drift is only where the model's air velocity (airspeed
    # along the heading) differs from the aircraft's (sideslip, climb), not moving air.
    gusts: bool = False
    # With the vertical action set (`actions`), climbing (descending) the autopilot's height
    # target is this far below the flight area's ceiling (above its floor), where it levels
    # off, reached at climb_rate_mps.
    vertical_margin_m: float = 20.0
    # The alerting stage of `mcts_daa` (uavxai.avoidance.alerting): the tree decides only while
    # an intruder is predicted inside the well-clear cylinder (alert_well_clear_m) within
    # alert_horizon_s (DO-365's 55 s), and for alert_hold_s after the last such prediction;
    # otherwise the ownship flies its route.
    alert_horizon_s: float = 55.0
    alert_hold_s: float = 5.0
    # The tree's conflict volume around each intruder (`conflict_volume`): "sphere", 3-D
    # separation below d_min_m; "cylinder", horizontal separation below d_min_m and vertical
    # below conflict_half_height_m (None: d_min_m, the cylinder holding that sphere).
    # Margins (intruder_margin) grow the cylinder keeping its aspect: a margin m adds m
    # horizontally and m * half-height / d_min_m vertically (the model's cylinder norm).
    conflict_half_height_m: float | None = None
    # Graded separation, nmac_cost, is a schema setting (`avoidance.mcts.nmac_cost`, issue
    # 32's fleet mission; `mcts_sep` sets it to 0.5): a line that comes inside a track's NMAC
    # cylinder (nmac_m; its horizontal miss less the track's margin, intruder_margin) keeps
    # 1 - nmac_cost x its depth (kernel.nmac_depth: 0 at the rim, 1 at d_min_m) of its value,
    # its deepest intrusion counting; the conflict at d_min_m stays the hard one.
    # Walls in the leaf value, wall_slack_s, is a schema setting too
    # (`avoidance.mcts.wall_slack_s`, issue 32's fleet mission; `mcts_sep` sets it to 4): a
    # leaf heading for a wall keeps the share of its value that its slack (seconds before it
    # must turn away at the bank limit to stay in the area) is of wall_slack_s
    # (kernel.wall_factor), and so does a line's late collision, by its edge's end (issue 31:
    # a meeting re-planning may still turn into a miss is worth something only if the ownship
    # is still in the area); 0: the walls are ignored (the paper).

    def __post_init__(self) -> None:
        values = {name: getattr(self, name) for name in SCHEMA_PATHS}
        for name, value in check_schema_settings(values, "PlannerConfig").items():
            object.__setattr__(self, name, value)  # as the schema keeps it (tuples, floats)
        self._check_own_settings()

    def _check_own_settings(self) -> None:
        """The planner-only settings' checks (the schema checked its own)."""
        hh = self.conflict_half_height_m
        if hh is not None and not hh > 0:
            raise UserError(f"PlannerConfig.conflict_half_height_m must be > 0 or None, got {hh}.")
        if self.vertical_reach_mps is not None and (
            self.conflict_volume != "sphere" or self.risk != "margin"
        ):
            raise UserError(
                "PlannerConfig.vertical_reach_mps (avoidance.mcts.vertical_reach_mps) needs "
                "conflict_volume 'sphere' and risk 'margin': it gives the sphere's margin a "
                "vertical part of its own."
            )
        if self.intruder_model not in INTRUDER_MODELS:
            raise UserError(
                f"PlannerConfig.intruder_model must be one of {', '.join(INTRUDER_MODELS)}, "
                f"got {self.intruder_model!r}."
            )
        if not 0 <= self.nmac_cost < 1:
            raise UserError(
                f"PlannerConfig.nmac_cost must be in [0, 1) (a line inside the NMAC volume "
                f"keeps some value: the collision stays the hard conflict), got {self.nmac_cost}."
            )
        for name in ("late_collision_value", "alert_horizon_s", "alert_hold_s", "wall_slack_s",
                     "pinned_slack_s"):  # fmt: skip
            if not getattr(self, name) >= 0:
                raise UserError(f"PlannerConfig.{name} must be >= 0, got {getattr(self, name)}.")
        # A time-out through the NMAC volume keeps 0.1 x (1 - nmac_cost) of its value, and a
        # collision at the horizon's end is worth late_collision_value: it may at most tie
        # with that deepest time-out (mcts_sep: 0.05 and 0.05), never outrank it.
        floor = 0.1 * (1.0 - self.nmac_cost)
        if self.late_collision_value >= 0.1 or self.late_collision_value > floor:
            raise UserError(
                "PlannerConfig.late_collision_value must be below the time-out's value 0.1 and "
                f"at most its least value through the NMAC volume, 0.1 x (1 - nmac_cost) = "
                f"{floor:g}; got {self.late_collision_value}."
            )
        if self.nmac_cost > 0 and not self.d_min_m < self.nmac_m[0]:
            # the NMAC depth is graded from the cylinder's rim to d_min_m (kernel.nmac_depth)
            raise UserError(
                f"PlannerConfig.nmac_cost > 0 grades the NMAC volume down to the collision "
                f"distance, so d_min_m ({self.d_min_m} m) must be below the NMAC horizontal "
                f"distance ({self.nmac_m[0]} m); lower avoidance.d_min_m, or set "
                "avoidance.mcts.nmac_cost: 0 and use another planner than mcts_sep."
            )
        lo, hi = self.climb_speed_band_mps
        if not lo < hi:
            raise UserError("PlannerConfig.climb_speed_band_mps must be (min, max) with min < max.")
        for name in ("roll_rate_limit_deg_s", "climb_rate_mps", "substep_s"):
            if not getattr(self, name) > 0:
                raise UserError(f"PlannerConfig.{name} must be > 0, got {getattr(self, name)}.")
        lo, hi = self.h_bounds
        if not 0 <= self.vertical_margin_m < 0.5 * (hi - lo):
            raise UserError(
                "PlannerConfig.vertical_margin_m must be >= 0 and below half the height band "
                f"{self.h_bounds}, got {self.vertical_margin_m}."
            )

    @classmethod
    def from_scenario(cls, scenario: Scenario, **overrides: object) -> PlannerConfig:
        """The planner settings of a scenario: its `avoidance` section, world bounds and seed."""
        from uavxai.dynamics.environment import EnvironmentConfig  # jsbsim only when asked
        from uavxai.scenario import aircraft_height_loop, aircraft_roll_rate_deg_s

        env = EnvironmentConfig.from_scenario(scenario)

        fields = {
            **schema_settings(scenario.avoidance, scenario.world),
            "roll_rate_limit_deg_s": aircraft_roll_rate_deg_s(scenario.ownship.aircraft),
            "climb_rate_mps": aircraft_height_loop(scenario.ownship.aircraft)[1],
            "seed": scenario.seed,
            "wind_mps": env.wind_enu[:2],
            "gusts": env.turbulence != "none",
            "climb_speed_band_mps": climb_speed_band(env.gust_airspeed_sigma_mps()),
        }
        fields.update(overrides)
        return cls(**fields)  # type: ignore[arg-type]

    @property
    def n_actions(self) -> int:
        """How many actions the set offers: the first ``n_actions`` of the table."""
        return ACTION_SETS[self.actions]

    def height_target(self, vertical: int, goal_h: float) -> float:
        """The height the autopilot is given under the vertical command ``vertical``: the
        leg's (the goal's) at 0; climbing (+1) the ceiling less ``vertical_margin_m``,
        descending (-1) the floor plus it, so that the autopilot climbs or sinks at its rate
        limit until it levels off there."""
        lo, hi = self.h_bounds
        if vertical > 0:
            return hi - self.vertical_margin_m
        if vertical < 0:
            return lo + self.vertical_margin_m
        return goal_h

    def vertical_of(self, alt_target_m: float | None) -> int:
        """The vertical command an autopilot height target stands for (the inverse of
        :meth:`height_target`; 0 for any other height, and always with the paper set)."""
        if self.actions == "paper" or alt_target_m is None:
            return 0
        for vertical in (1, -1):  # within the float32 the command travels as
            if abs(alt_target_m - self.height_target(vertical, math.nan)) < 1e-3:
                return vertical
        return 0

    def whole_goal(self) -> PlannerConfig:
        """This config with the goal's whole sphere (``goal_margin_m`` 0): for the planners
        that do not search toward the goal (`mvp`, `none`, the learned ones), whose
        evidence (decisions.jsonl) is to show the judge's goal, not a tree's aim."""
        return replace(self, goal_margin_m=0.0) if self.goal_margin_m else self

    @property
    def goal_aim_m(self) -> float:
        """The radius within which the tree counts the goal reached: the scenario's
        ``goal_radius_m`` less ``goal_margin_m`` (the judge counts the whole radius)."""
        return self.goal_radius_m - self.goal_margin_m

    @property
    def cylinder_aspect(self) -> float | None:
        """The conflict cylinder's radius / half-height, by which the model scales heights
        into its cylinder norm ``max(|r_xy|, aspect |r_h|)``; None: the sphere."""
        if self.conflict_volume != "cylinder":
            return None
        hh = self.conflict_half_height_m
        return 1.0 if hh is None else self.d_min_m / hh

    @property
    def cull_factor(self) -> float:
        """How much farther (3-D) than ``d_min_m`` plus margin an intruder may be and still
        conflict: 1 for the sphere; for the cylinder its corner, ``hypot(1, 1 / aspect)``."""
        aspect = self.cylinder_aspect
        return 1.0 if aspect is None else math.hypot(1.0, 1.0 / aspect)

    @property
    def cull_m(self) -> float:
        """The conflict distance culling uses: ``d_min_m`` (sphere) or the cylinder's
        corner distance."""
        return self.d_min_m if self.cylinder_aspect is None else self.d_min_m * self.cull_factor

    @property
    def bank_limit_rad(self) -> float:
        return math.radians(self.bank_limit_deg)

    @property
    def bank_step_rad(self) -> float:
        return math.radians(self.bank_step_deg)

    @property
    def d_max(self) -> float:
        """Normaliser of the leaf value 1 - d/d_max: the diagonal of the flight area."""
        return math.dist(
            (self.x_bounds[0], self.y_bounds[0], self.h_bounds[0]),
            (self.x_bounds[1], self.y_bounds[1], self.h_bounds[1]),
        )


@dataclass(frozen=True)
class Meeting:
    """Where a line conflicts: the first intruder it comes inside the separation it needs
    from (``d_min`` plus the margin that intruder's possible manoeuvres and track error add,
    see :func:`uavxai.avoidance.model.intruder_margin`)."""

    intruder: int | str
    time_s: float  # from the decision to the start of the sub-step where it comes inside, s
    miss_m: float  # the closest the line comes to that intruder's predicted track, m
    needed_m: float  # the separation it needed there, m


@dataclass(frozen=True)
class ChildStats:
    """What the search learnt about one root action.

    The separations are predictions: the ownship flying the line (the action, then the
    search's most visited continuation), every intruder flying on as predicted (its tracked
    velocity, or its turn with ``intruder_model`` ct/reachable), without margins; a line
    that collides is measured to the end of its last level (its predicted miss), one that
    reaches the goal or leaves the area up to there.
    """

    action: int  # index into uavxai.vocabulary.ACTIONS (0..8 the paper's, 9..10 vertical)
    bank_cmd_rad: float  # the bank command this action leads to
    accel_mps2: float
    visits: int
    q: float  # mean backed-up value
    predicted_min_separation_m: float  # along the best line below this action
    closest_intruder: int | str | None  # id of the intruder that comes closest on that line
    time_to_closest_s: float | None = None  # from the decision, s
    outcome: str = ""  # how that line ends: goal, collision, out_of_bounds, timeout or "" (open)
    collision_share: float | None = None  # MCTS: share of this action's simulations that collided
    alt_target_m: float | None = None  # the height target it gives (None: the paper set's)
    meets: Meeting | None = None  # the line's first conflict (None: it has none)
    # the action whose manoeuvre this one flies once its commands are clamped (a bank step
    # beyond the bank limit, a speed change beyond the speed limit); None: itself
    effect: int | None = None
    # other intruders whose track error could bring them closer than ``closest_intruder`` on
    # that line: (id, closest approach on its predicted track less its margin there, m)
    unsure: tuple[tuple[int | str, float], ...] = ()
    # with risk as a probability (PlannerConfig.risk): the chance that line loses separation
    # with each intruder, (id, chance) the likeliest first, and with any (None: not weighed)
    losses: tuple[tuple[int | str, float], ...] = ()
    risk: float | None = None
    # the line ends (open, or meeting an intruder) where the ownship can no longer turn away
    # from a wall (kernel.wall_factor 0): as good as leaving the area. Planners with
    # wall_slack_s only (`mcts_sep`); always False for the others.
    trapped: bool = False
    # with graded separation (`nmac_cost`): the line's deepest NMAC intrusion as the search
    # graded it (kernel.nmac_depth: 0 none, 1 at d_min_m); 0 for the planners that grade none
    nmac_depth: float = 0.0
    # with pinning weighed (`avoidance.mcts.pinned_slack_s`): the tracks that pin the line's
    # open end against the floor or the ceiling, (id, share of the line's value it leaves),
    # the tightest first (kernel.pin_share); () for a line that ends otherwise or is not pinned
    pinned: tuple[tuple[int | str, float], ...] = ()

    @property
    def flies(self) -> int:
        """The action this one really flies (itself unless clamped into another)."""
        return self.action if self.effect is None else self.effect

    @property
    def clear(self) -> bool:
        """No conflict on the line as the search sees one: no meeting, and (graded
        separation) no NMAC intrusion. The line a detect-and-avoid route keeps
        (`alerting.py`)."""
        return self.meets is None and self.nmac_depth == 0.0


@dataclass
class SearchTree:
    """The whole search tree as flat arrays (node 0 is the root). Explanation is data."""

    parent: np.ndarray  # (M,) int, -1 for the root
    action: np.ndarray  # (M,) int, the action that led here (-1 for the root)
    depth: np.ndarray  # (M,) int
    visits: np.ndarray  # (M,) int
    value_sum: np.ndarray  # (M,) float
    min_sep: np.ndarray  # (M,) float, predicted min separation along the edge into this node
    closest: np.ndarray  # (M,) int, index (0-based, into the intruder list) of the closest one
    terminal: np.ndarray  # (M,) int8: uavxai.avoidance.model.TERMINALS' codes, 0 none
    pos: np.ndarray  # (M, 3) ownship position at the node, for drawing the tree in 3-D
    t_closest: np.ndarray | None = None  # (M,) s from the decision to that closest approach
    state: np.ndarray | None = None  # (M, 7) encounter-model state (x, y, h, V, psi, phi, cmd)
    # (M,) index of a node's first child when children are stored as consecutive blocks of
    # ``branching`` (as the search builds them), -1 without children; None: look them up by
    # parent
    first_child: np.ndarray | None = None
    branching: int = N_ACTIONS  # children per expanded node: the action set's size
    # the time the episode had left when the search valued its lines: a line still open
    # then ends ``timeout`` (inf: no time-out in sight)
    time_left_s: float = math.inf
    # (M,) with risk as a probability (PlannerConfig.risk): the chance that the line from the
    # root to the node loses separation with some track, which weighted its value; None: off
    risk: np.ndarray | None = None
    # How a node's children are ranked (best_child): False, by visits then Q (MCTS's mean
    # backup: the most visited is the most trusted); True, by Q then visits (the best-value
    # backup, `avoidance.mcts.backup: best`, where Q is the best line found below a child).
    # The exhaustive search visits each node once, so either ranks its children by Q.
    by_value: bool = False
    # (M,) with graded separation (PlannerConfig.nmac_cost > 0): the deepest NMAC intrusion
    # on the line from the root to the node, as the search graded it (kernel.nmac_depth: 0
    # none, 1 at d_min_m); None: not graded
    nmac_depth: np.ndarray | None = None
    # (M,) with the best-value backup: the best value a walk through the node scored, exactly.
    # Q is read from it, not as value_sum / visits, which rounds (best * n / n differs from
    # best in the last bit for about one node in eight) and would break ties between equally
    # good lines by that noise instead of by visits, then action order.
    best: np.ndarray | None = None

    @property
    def q(self) -> np.ndarray:
        if self.best is not None:
            return np.where(self.visits > 0, self.best, 0.0)
        return np.divide(self.value_sum, np.maximum(self.visits, 1))

    @property
    def size(self) -> int:
        return int(self.parent.shape[0])

    def children_of(self, node: int) -> np.ndarray:
        if self.first_child is not None:
            first = int(self.first_child[node])
            if first < 0:
                return np.zeros(0, dtype=int)
            return np.arange(first, first + self.branching)
        return np.flatnonzero(self.parent == node)

    def best_child(self, node: int) -> int | None:
        """The most visited child of ``node`` (ties: higher Q, then lower action), or with
        ``by_value`` the one with the highest Q (ties: more visits, then lower action); None
        when no child was visited."""
        kids = self.children_of(node)
        best, chosen = None, None
        values = (self.value_sum if self.best is None else self.best)[kids].tolist()
        # a few children: plain Python numbers cost less than array calls (and divide alike)
        for kid, n, value, action in zip(kids.tolist(), self.visits[kids].tolist(), values,
                                         self.action[kids].tolist(), strict=True):  # fmt: skip
            if n == 0:
                continue
            q = value if self.best is not None else value / n
            rank = (-q, -n, action) if self.by_value else (-n, -q, action)
            if best is None or rank < best:
                best, chosen = rank, kid
        return chosen

    def best_line(self, node: int) -> list[int]:
        """``node`` and the path of best children below it (:meth:`best_child`): what the
        search expects to follow."""
        line = [node]
        while (nxt := self.best_child(line[-1])) is not None:
            line.append(nxt)
        return line

    def pruned(self, min_visits: int = 1) -> SearchTree:
        """The nodes visited at least ``min_visits`` times (and the root), renumbered.

        A search caches the states of children it never visits; drawing or storing the tree
        usually wants only what the search actually looked at.
        """
        keep = self.visits >= min_visits
        keep[0] = True
        old = np.flatnonzero(keep)
        new_index = np.full(self.size, -1)
        new_index[old] = np.arange(old.size)
        parent = self.parent[old]
        return SearchTree(
            parent=np.where(parent >= 0, new_index[np.maximum(parent, 0)], -1),
            action=self.action[old],
            depth=self.depth[old],
            visits=self.visits[old],
            value_sum=self.value_sum[old],
            min_sep=self.min_sep[old],
            closest=self.closest[old],
            terminal=self.terminal[old],
            pos=self.pos[old],
            t_closest=None if self.t_closest is None else self.t_closest[old],
            state=None if self.state is None else self.state[old],
            time_left_s=self.time_left_s,
            risk=None if self.risk is None else self.risk[old],
            by_value=self.by_value,
            nmac_depth=None if self.nmac_depth is None else self.nmac_depth[old],
            best=None if self.best is None else self.best[old],
        )


@dataclass
class Decision:
    """One decision of a planner (README, planner API), with what it is based on.

    ``predicted_min_separation_m`` is the smallest 3-D separation the planner predicts over
    the *next decision period* only (the chosen action held for ``decision_period_s``, every
    intruder on its predicted track (constant velocity, or its turn with ``intruder_model``
    ct/reachable; no margin added), closest approach solved exactly).
    ``branch_min_separation_m`` is what the explanation quotes and the trust figure checks:
    the same prediction over the chosen branch's whole planned line, which reaches
    ``branch_horizon_s`` ahead (see :class:`ChildStats`).
    """

    bank_cmd_rad: float
    accel_mps2: float
    action: int
    children: list[ChildStats]
    tree: SearchTree | None = None
    plan: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (P, 3) chosen branch
    predicted_min_separation_m: float = math.inf
    confidence: float = 0.0  # share of root visits that went to the chosen action
    ms: float = 0.0  # planner wall time
    branch_min_separation_m: float = math.inf  # along the chosen line, depth x action_hold_s
    branch_horizon_s: float = 0.0  # how far ahead the chosen line reaches, s
    # every option conflicted and the planner chose by uavxai.avoidance.lines.cornered_key
    cornered: bool = False
    # the route's line had no conflict, so the route's action was taken whatever the search
    # preferred (`mcts_daa`: a detect-and-avoid system leaves its route only to avoid)
    route_kept: bool = False
    planner: str = ""  # which planner decided (mcts, exhaustive, none, ...)
    # the search ranked its options by Q first (the best-value backup, SearchTree.by_value)
    by_value: bool = False
    d_min_m: float = 50.0  # the collision distance the planner worked with
    # the rule a cornered decision chose by (`avoidance.mcts.cornered_rule`, lines.cornered_key)
    cornered_rule: str = "latest"
    # (explanation, counterfactual) in words. Planners return evidence and leave this None;
    # the words are made on first use by the narrator uavxai.xai registers (set_narrator).
    words: tuple[str, str] | None = None
    # The vertical command: the height target the autopilot is given with this action (the
    # vertical action set; a climb aims at the ceiling and climbs at the rate limit). None:
    # unchanged, the leg's height (the paper's nine).
    alt_target_m: float | None = None
    # What the operator on a ground station asked for, when the decision was taken under an
    # operator's aim (uavxai.sim.operator): the explanation opens with it.
    aim: str = ""

    @property
    def explanation(self) -> str:
        """The decision in one sentence (README, planner API)."""
        return self._narrated()[0]

    @property
    def counterfactual(self) -> str:
        """Why not the runner-up."""
        return self._narrated()[1]

    def _narrated(self) -> tuple[str, str]:
        if self.words is None:
            self.words = _NARRATOR[0](self) if _NARRATOR else ("", "")
            if self.aim:
                self.words = (f"{self.aim}: {self.words[0]}", self.words[1])
        return self.words

    def to_json(self) -> dict:
        """The per-decision fields of decisions.jsonl that come from the planner."""
        return {
            "planner": self.planner,
            "action": {
                "bank_cmd_rad": self.bank_cmd_rad,
                "accel_mps2": self.accel_mps2,
                "index": int(self.action),
                "name": action_name(self.action),
                "alt_target_m": self.alt_target_m,
            },
            "children": [
                {
                    "action": {
                        "index": c.action,
                        "bank_cmd_rad": c.bank_cmd_rad,
                        "accel_mps2": c.accel_mps2,
                        "name": action_name(c.action),
                        "alt_target_m": c.alt_target_m,
                    },
                    "visits": int(c.visits),
                    "q": float(c.q),
                    "predicted_min_separation_m": _finite(c.predicted_min_separation_m),
                    "closest_intruder": c.closest_intruder,
                    "time_to_closest_s": c.time_to_closest_s,
                    "outcome": c.outcome,
                    "collision_share": c.collision_share,
                    "meets": None if c.meets is None else asdict(c.meets),
                    "flies": action_name(c.flies),
                    "unsure": [[who, m] for who, m in c.unsure],
                    # with risk as a probability only: the line's chance of losing separation
                    **({} if c.risk is None else {
                        "risk": c.risk, "losses": [[who, p] for who, p in c.losses]}),
                    # planners that weigh the walls: the line ends unable to turn away from one
                    **({"trapped": True} if c.trapped else {}),
                    # planners that grade NMAC intrusion (nmac_cost > 0): how deep the line
                    # comes into a track's NMAC cylinder (0 at the rim, 1 at d_min_m); with
                    # mcts_sep_daa a route line with one is not kept, though it meets no one
                    **({"nmac_depth": c.nmac_depth} if c.nmac_depth > 0 else {}),
                    # planners that weigh pinning (pinned_slack_s > 0): the tracks the line's
                    # end lies pinned by against the floor or the ceiling, [id, share kept]
                    **({"pinned": [[who, v] for who, v in c.pinned]} if c.pinned else {}),
                }
                for c in self.children
            ],
            "explanation": self.explanation,
            "counterfactual": self.counterfactual,
            "confidence": self.confidence,
            "predicted_min_separation_m": _finite(self.predicted_min_separation_m),
            "branch_min_separation_m": _finite(self.branch_min_separation_m),
            "branch_horizon_s": self.branch_horizon_s,
            "cornered": self.cornered,
            # another rule than the default's, when it chose (files of "latest" stay as they were)
            **({"cornered_rule": self.cornered_rule}
               if self.cornered and self.cornered_rule != "latest" else {}),
            "route_kept": self.route_kept,
            "d_min_m": self.d_min_m,
            # the episode's time left that the search valued its lines against (None: no tree)
            "time_left_s": None if self.tree is None else _finite(self.tree.time_left_s),
            "ms": self.ms,
        }


Goal = tuple[float, float, float]

# Who turns a decision's evidence into words: registered by uavxai.xai (a layer above), so
# that planners stay free of prose and xai free of planners' internals.
_NARRATOR: list = []


def set_narrator(narrate) -> None:
    """Register ``narrate(decision) -> (explanation, counterfactual)``."""
    _NARRATOR[:] = [narrate]


def check_plan_inputs(own: Ownship, intruders: Sequence[Intruder], goal: Goal) -> None:
    """A UserError for inputs no planner can work with: non-finite numbers, a stalled
    ownship, a goal that is not (x, y, h)."""
    if len(goal) != 3 or not all(math.isfinite(float(g)) for g in goal):
        raise UserError(f"goal must be three finite numbers (x, y, h) in metres, got {goal!r}")
    values = (own.x, own.y, own.h, own.speed, own.heading, own.bank, *(own.ground_velocity or ()))
    if not all(math.isfinite(v) for v in values) or (
        own.phi is not None and not math.isfinite(own.phi)
    ):
        raise UserError(f"the ownship has a non-finite field: {own}")
    if own.speed <= 0:
        raise UserError(f"the ownship speed must be > 0 m/s, got {own.speed}")
    for i in intruders:
        if not all(math.isfinite(v) for v in (i.x, i.y, i.h, i.vx, i.vy, i.vh)):
            raise UserError(f"intruder {i.id} has a non-finite field: {i}")


@runtime_checkable
class Planner(Protocol):
    """What every avoidance planner offers (MCTS, the baselines, the learned ones).

    ``plan`` sees the world as it is now and returns one of its action set's actions (the
    paper's 9, or with ``config.actions == "vertical"`` 11) as a Decision.
    ``step`` places the episode's time-out: the planner sees it ``config.max_steps - step``
    decisions ahead. A transit-only episode passes the decisions it has taken; an episode
    whose own limit is longer (a mission: transit, station and return) passes the step that
    makes this its own remaining decisions (negative then). Library users who do not count
    may leave it at 0.
    ``reset`` re-seeds whatever randomness the planner uses: same seed, same decisions.
    """

    name: str
    config: PlannerConfig

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision: ...

    def reset(self, seed: int) -> None: ...


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None
