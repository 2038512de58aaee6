"""The head-on encounter the operator tests fly: the ownship north from (1000, 700) to a goal
1.2 km ahead, one intruder coming south at it from 800 m, exact surveillance. Flown without
an operator it clears by more than d_min; issue 28 measured it colliding after one operator
command when a command switched avoidance off."""

from __future__ import annotations

GOAL = (1000.0, 1900.0, 120.0)
HEAD_ON = {
    "ownship": {
        "start": {"x": 1000, "y": 700, "h": 120, "heading_deg": 0, "speed_mps": 20},
        "goal": list(GOAL),
    },
    "intruders": {"list": [{"x": 1000, "y": 1500, "h": 120, "heading_deg": 180,
                            "speed_mps": 20}]},  # fmt: skip
    "surveillance": {"model": "truth"},
    "avoidance": {"planner": "mcts_fast", "max_steps": 150},
    "log": {"rerun": False},
}
