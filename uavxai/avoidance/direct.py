"""The `none` planner: no avoidance, steer straight for the goal (a floor for the others).

A proportional heading controller: the bank wanted is ``HEADING_GAIN`` times the heading error
to the goal, clamped to the bank limit; the planner takes whichever of left / hold / right
brings the bank command closest to it, at constant speed. It uses the same 9 actions as the
others, so its commands take the same path to the aircraft.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence

import numpy as np

from uavxai.avoidance.mcts import intruder_arrays
from uavxai.avoidance.model import EncounterModel, accel_command, bank_command, ownship_state
from uavxai.avoidance.types import (
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
    check_plan_inputs,
)
from uavxai.geometry import bearing, wrap_angle
from uavxai.vocabulary import CLIMB, DESCEND

HEADING_GAIN = 1.0  # rad of bank per rad of heading error
HOLD_SPEED = 1  # accel index of "hold speed"
NAME = "none"  # the registered name: the floor the DAA columns are measured against


def heading_action(own: Ownship, goal: Goal, cfg: PlannerConfig) -> int:
    """The `none` planner's action: the bank step nearest a bank proportional to the heading
    error to the goal, at constant speed."""
    error = wrap_angle(bearing(goal[0] - own.x, goal[1] - own.y) - own.heading)
    wanted = max(-cfg.bank_limit_rad, min(cfg.bank_limit_rad, HEADING_GAIN * error))
    # Bank actions 0, 1, 2 (left, hold, right); ties go to holding.
    options = [float(bank_command(own.bank, 3 * b + HOLD_SPEED, cfg)) for b in range(3)]
    b = min((1, 0, 2), key=lambda i: abs(options[i] - wanted))
    return 3 * b + HOLD_SPEED


def route_action(own: Ownship, goal: Goal, cfg: PlannerConfig) -> int:
    """The action that flies the route: back to the leg's height when a vertical command is
    on (one step of it), else :func:`heading_action`."""
    if own.vertical:
        return CLIMB if own.vertical < 0 else DESCEND
    return heading_action(own, goal, cfg)


class DirectPlanner:
    """Fly at the goal, ignoring every intruder."""

    def __init__(self, config: PlannerConfig | None = None, *, name: str = NAME) -> None:
        self.config = (config or PlannerConfig()).whole_goal()
        self.name = name
        self.model = EncounterModel(self.config)

    def reset(self, seed: int) -> None:
        """Nothing random to re-seed."""

    def action(self, own: Ownship, goal: Goal) -> int:
        """The action this planner takes (what :meth:`plan` decides, without the prediction
        that explains it)."""
        return heading_action(own, goal, self.config)

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        t0 = time.perf_counter()
        check_plan_inputs(own, intruders, goal)
        action = self.action(own, goal)
        error = wrap_angle(bearing(goal[0] - own.x, goal[1] - own.y) - own.heading)
        cfg = self.config
        pos, vel = intruder_arrays(intruders)
        period = cfg.decision_period_s
        goal_xyz = np.asarray(goal, dtype=float)
        seg = self.model.fly(
            ownship_state(own)[None],
            np.array([action]),
            goal_xyz,
            period,
            self.model.predict(pos, vel, period, index=False),
            cull=False,
            exact=True,
        )
        return Decision(
            bank_cmd_rad=float(bank_command(own.bank, action, cfg)),
            accel_mps2=float(accel_command(action, cfg)),
            action=action,
            children=[],
            words=(
                f"no avoidance: steering for the goal ({math.degrees(error):+.0f} deg off "
                f"the nose, {math.dist((own.x, own.y, own.h), goal):.0f} m away)",
                "",
            ),
            plan=seg.samples[0],
            predicted_min_separation_m=float(seg.min_sep[0]),
            # its plan is this one period, and that is what the trust figure checks
            branch_min_separation_m=float(seg.min_sep[0]),
            branch_horizon_s=period,
            confidence=1.0,
            ms=1000.0 * (time.perf_counter() - t0),
            planner=self.name,
            d_min_m=cfg.d_min_m,
        )
