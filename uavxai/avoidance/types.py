"""Planner API types (SPEC §7): what goes into a planner and what comes out.

These are plain data so that a planner works without JSBSim, MAVLink or rerun. Headings are
radians clockwise from north (aviation convention); positions ENU metres.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np

# The 9 actions: index = 3 * bank_index + accel_index.
BANK_CHOICES = (-1, 0, +1)  # left, hold, right: one bank_step_deg change of the bank command
ACCEL_CHOICES = (+1, 0, -1)  # speed up, hold, slow down: times accel_mps2
BANK_NAMES = ("left", "hold", "right")
ACCEL_NAMES = ("speed up", "hold speed", "slow down")
N_ACTIONS = 9


def action_parts(a: int) -> tuple[int, int]:
    """(bank sign, accel sign) of action index ``a``."""
    return BANK_CHOICES[a // 3], ACCEL_CHOICES[a % 3]


def action_name(a: int) -> str:
    b, c = a // 3, a % 3
    bank = {0: "bank left", 1: "hold bank", 2: "bank right"}[b]
    return f"{bank}, {ACCEL_NAMES[c]}"


@dataclass(frozen=True)
class Ownship:
    x: float
    y: float
    h: float
    speed: float  # m/s along the track
    heading: float  # rad, clockwise from north
    bank: float = 0.0  # rad, right wing down positive (the current bank command)


@dataclass(frozen=True)
class Intruder:
    id: int | str
    x: float
    y: float
    h: float
    vx: float  # east, m/s
    vy: float  # north, m/s
    vh: float = 0.0  # up, m/s


@dataclass(frozen=True)
class PlannerConfig:
    """Fields as the scenario's `avoidance` section, plus the flight-area bounds."""

    x_bounds: tuple[float, float] = (0.0, 2000.0)
    y_bounds: tuple[float, float] = (0.0, 2000.0)
    h_bounds: tuple[float, float] = (50.0, 300.0)
    d_min_m: float = 50.0
    goal_radius_m: float = 50.0
    decision_period_s: float = 1.0
    max_steps: int = 400
    bank_limit_deg: float = 30.0
    bank_step_deg: float = 10.0
    accel_mps2: float = 1.0
    speed_mps: tuple[float, float] = (12.0, 30.0)
    simulations: int = 200
    depth: int = 4
    c: float = 1.0
    action_hold_s: float = 4.0
    roll_rate_limit_deg_s: float = 30.0  # matches the JSBSim autopilot's roll-rate limit
    seed: int = 0

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
class ChildStats:
    """What the search learnt about one root action."""

    action: int  # 0..8
    bank_cmd_rad: float  # the bank command this action leads to
    accel_mps2: float
    visits: int
    q: float  # mean backed-up value
    predicted_min_separation_m: float  # along the best line below this action
    closest_intruder: int | str | None  # id of the intruder that comes closest on that line
    time_to_closest_s: float | None = None


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
    terminal: np.ndarray  # (M,) int8: 0 none, 1 goal, 2 collision, 3 out of bounds, 4 time-out
    pos: np.ndarray  # (M, 3) ownship position at the node, for drawing the tree in 3-D

    @property
    def q(self) -> np.ndarray:
        return np.divide(self.value_sum, np.maximum(self.visits, 1))

    @property
    def size(self) -> int:
        return int(self.parent.shape[0])

    def children_of(self, node: int) -> np.ndarray:
        return np.flatnonzero(self.parent == node)


@dataclass
class Decision:
    bank_cmd_rad: float
    accel_mps2: float
    action: int
    children: list[ChildStats]
    explanation: str
    tree: SearchTree | None = None
    plan: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # (P, 3) chosen branch
    predicted_min_separation_m: float = math.inf
    confidence: float = 0.0  # share of root visits that went to the chosen action
    ms: float = 0.0  # planner wall time
    counterfactual: str = ""  # why not the runner-up

    def to_json(self) -> dict:
        """The per-decision fields of decisions.jsonl that come from the planner."""
        return {
            "action": {"bank_cmd_rad": self.bank_cmd_rad, "accel_mps2": self.accel_mps2},
            "children": [
                {
                    "action": {
                        "index": c.action,
                        "bank_cmd_rad": c.bank_cmd_rad,
                        "accel_mps2": c.accel_mps2,
                        "name": action_name(c.action),
                    },
                    "visits": int(c.visits),
                    "q": float(c.q),
                    "predicted_min_separation_m": _finite(c.predicted_min_separation_m),
                    "closest_intruder": c.closest_intruder,
                    "time_to_closest_s": c.time_to_closest_s,
                }
                for c in self.children
            ],
            "explanation": self.explanation,
            "counterfactual": self.counterfactual,
            "confidence": self.confidence,
            "predicted_min_separation_m": _finite(self.predicted_min_separation_m),
            "ms": self.ms,
        }


def _finite(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None
