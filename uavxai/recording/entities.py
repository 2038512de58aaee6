"""Entity paths and timelines of the recording (SPEC §5), shared by the recorder and blueprint."""

from __future__ import annotations

SIM_TIME = "sim_time"  # duration timeline, simulated seconds
DECISION = "decision"  # sequence timeline, one step per planner decision

WORLD = "world"
OWNSHIP = "world/ownship"
OWNSHIP_TRAIL = "world/ownship/trail"
INTRUDERS = "world/intruders"
INTRUDER_TRAILS = "world/intruders/trails"  # all intruder trails, one strip each per row
USERS = "world/users"
SERVICE_POINT = "world/service_point"
SEARCH_PATH = "world/service_search"
PLAN = "world/plan"
GOAL = "world/goal"
BOUNDS = "world/bounds"

TREE = "xai/tree"
EXPLANATION = "xai/explanation"
METRICS = "metrics"

# The metric names the pipeline logs, in the order the blueprint shows them.
METRIC_NAMES = ("sum_rate_bps", "min_separation_m", "bank_deg", "airspeed_mps", "decision_ms")


def intruder_path(aircraft_id: str, fallback_n: int) -> str:
    """``world/intruders/N`` for ``intruder-N``; other ids keep their position in the list."""
    prefix, _, tail = aircraft_id.rpartition("-")
    n = tail if prefix == "intruder" and tail.isdigit() else str(fallback_n)
    return f"{INTRUDERS}/{n}"


def metric_path(name: str) -> str:
    return f"{METRICS}/{name}"
