"""Entity paths and timelines of the recording (docs/recording), shared by the recorder and
blueprint."""

from __future__ import annotations

SIM_TIME = "sim_time"  # duration timeline, simulated seconds
DECISION = "decision"  # sequence timeline, one step per planner decision

WORLD = "world"
OWNSHIP = "world/ownship"
OWNSHIP_TRAIL = "world/ownship/trail"  # trail_path(OWNSHIP)
INTRUDERS = "world/intruders"
INTRUDER_TRAILS = "world/intruders/trails"  # all intruder trails, one strip each per row
USERS = "world/users"
SERVICE_POINT = "world/service_point"
SEARCH_PATH = "world/service_search"
PLAN = "world/plan"
GOAL = "world/goal"
BOUNDS = "world/bounds"
LINKS = "world/links"  # UAV -> each served user, one strip per user
ORBIT = "world/orbit"  # the loiter circle in force
SERVICE_POINTS = "world/service_points"  # every service point chosen so far, labelled by time
TRACKS = "world/tracks"  # the planner's belief about intruder N under world/tracks/N

RATES = "service/rates"  # per-user rate bars, split so each bar has its QoS colour
RATES_AT_QOS = "service/rates/at_qos"
RATES_BELOW_QOS = "service/rates/below_qos"
RATES_QOS = "service/rates/qos"  # the QoS rate per user, drawn as a faint band behind the bars

MISSION = "mission"
PHASE = "mission/phase"  # TextLog, one row per phase change
STATUS = "mission/status"  # TextDocument: phase and service now, in words
PHASE_METRIC = "metrics/phase"  # the phase as a number (PHASES order), a step plot

MAP = "map"  # GeoPoints / GeoLineStrings in WGS-84, for the map view
MAP_OWNSHIP = "map/ownship"
MAP_INTRUDERS = "map/intruders"
MAP_USERS = "map/users"
MAP_ORBIT = "map/orbit"
MAP_SERVICE_POINTS = "map/service_points"

TREE = "xai/tree"
EXPLANATION = "xai/explanation"
METRICS = "metrics"

# The metric names the pipeline logs, in the order the blueprint shows them.
METRIC_NAMES = ("sum_rate_bps", "min_separation_m", "bank_deg", "airspeed_mps", "decision_ms")


# Mission phases in the order the phase plot numbers them (uavxai.sim.mission.Phase values);
# a phase not listed gets the next number when first seen.
PHASES = ("transit", "on_station", "avoiding", "returning")


def intruder_path(aircraft_id: str, fallback_n: int) -> str:
    """``world/intruders/N`` for ``intruder-N``; other ids keep their position in the list."""
    prefix, _, tail = aircraft_id.rpartition("-")
    n = tail if prefix == "intruder" and tail.isdigit() else str(fallback_n)
    return f"{INTRUDERS}/{n}"


def member_path(member_id: str) -> str:
    """``world/ownship-i`` for fleet member ``ownship-i`` (i >= 1; member 0 is
    ``world/ownship`` with everything N = 1 records); its trail below it, ``/trail``."""
    return f"{WORLD}/{member_id}"


def member_plan_path(member_id: str) -> str:
    """``world/ownship-i/plan``: member i's chosen plan (member 0's is ``world/plan``)."""
    return f"{member_path(member_id)}/plan"


def member_explanation_path(member_id: str) -> str:
    """``xai/ownship-i/explanation``: member i's explanations (member 0's are
    ``xai/explanation``, the ones the default blueprint shows)."""
    return f"xai/{member_id}/explanation"


def trail_path(aircraft_path: str) -> str:
    return f"{aircraft_path}/trail"


def metric_path(name: str) -> str:
    return f"{METRICS}/{name}"


def track_path(track_id: object) -> str:
    """``world/tracks/N`` for ``intruder-N`` (beside ``world/intruders/N``); other ids (e.g. an
    ICAO address) keep their own name, so a track keeps its path for its whole life."""
    text = str(track_id)
    prefix, _, tail = text.rpartition("-")
    name = tail if prefix == "intruder" and tail.isdigit() else text.replace("/", "_")
    return f"{TRACKS}/{name}"
