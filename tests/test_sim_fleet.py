"""A fleet in flight (issue 32, docs/fleet.md): the schema's refusals, the members in the one
JSBSim world, two members on a collision course resolved by their own planners, and a whole
`uavxai run` of scenarios/fleet.yaml whose delivered bits are recomputed from service.csv.
Real JSBSim and the real MCTS planner throughout."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest

from uavxai.cli import main
from uavxai.comms.delivery import SERVICE_COLUMNS
from uavxai.errors import ScenarioError
from uavxai.scenario import default_scenario, load_scenario
from uavxai.vocabulary import Outcome

FLEET = Path(__file__).resolve().parents[1] / "scenarios" / "fleet.yaml"
START = {"x": 150, "y": 1300, "h": 120, "heading_deg": 90, "speed_mps": 20}


def fleet_scenario(**over):
    base = {"fleet": {"size": 3}, "log": {"rerun": False}, "ownship": {"start": START}}
    return default_scenario("fleet-test", **{**base, **over})


# ----------------------------------------------------------------------------------- schema
@pytest.mark.parametrize(
    ("over", "named"),
    [
        ({"log": {"rerun": True}}, "log.rerun"),
        ({"ownship": {"start": START, "goal": [1800, 1000, 120]}}, "ownship.goal"),
        ({"mission": {"service_s": 0}}, "mission.service_s"),
        ({"avoidance": {"decision_latency_s": 0.5}}, "decision_latency_s"),
        ({"comms": {"users": {"count": 2}}}, "at least 3 users"),
        ({"ownship": {"start": {**START, "y": 400}}}, "outside the world"),
    ],
)
def test_a_fleet_refuses_what_it_cannot_fly_by_name(over: dict, named: str) -> None:
    with pytest.raises(ScenarioError, match="fleet.size = 3") as err:
        fleet_scenario(**over)
    assert named in str(err.value)


def test_members_start_abreast_to_the_right() -> None:
    starts = fleet_scenario().member_starts()
    assert [(round(s.x, 6), round(s.y, 6)) for s in starts] == [
        (150, 1300), (150, 1000), (150, 700)
    ]  # fmt: skip
    assert default_scenario("one").member_starts() == [default_scenario("one").ownship.start]


# ------------------------------------------------------------------------------------ world
def test_members_fly_in_the_world_after_the_intruders_each_on_its_own_commands() -> None:
    from uavxai.dynamics.world import JSBSimWorld

    sc = fleet_scenario(intruders={"count": 2})
    with JSBSimWorld(sc) as world:
        s = world.state()
        assert s.ids == ("ownship-0", "intruder-1", "intruder-2", "ownship-1", "ownship-2")
        assert list(world.member_rows) == [3, 4]
        np.testing.assert_allclose(s.pos[[0, 3, 4], 1], [1300, 1000, 700], atol=1.0)
        world.command_row(3, bank_cmd_rad=math.radians(25))  # member 1 turns right, alone
        world.lookahead(120, 12)  # the intruders may fly ahead; the members may not
        assert world.ahead_ticks > 0 and world._lead[3] == world._lead[4] == 0
        world.step(600)
        s = world.state()
        psi = np.degrees(s.att[:, 2])
        assert psi[3] > 120 and abs(psi[0] - 90) < 5 and abs(psi[4] - 90) < 5


def test_one_ownship_keeps_its_name() -> None:
    from uavxai.dynamics.world import JSBSimWorld

    with JSBSimWorld(default_scenario("one", intruders={"count": 1})) as world:
        assert world.state().ids == ("ownship", "intruder-1")
        assert list(world.member_rows) == []


# ------------------------------------------------------------------------- cooperation
def _crossing(sc):
    """Member 0 (y 1300) is sent south-east, member 1 (y 1000) north-east: flown straight,
    they meet where their legs cross, at the same time."""
    return np.array([[1350.0, 700.0, 120.0], [1350.0, 1600.0, 120.0]])


def test_two_members_on_a_collision_course_keep_clear_of_each_other() -> None:
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.build import fly
    from uavxai.sim.fleet import Fleet
    from uavxai.sim.spec import episode_spec
    from uavxai.sim.steps import Energy

    sc = fleet_scenario(
        fleet={"size": 2}, intruders={"count": 0}, mission={"service_s": 10, "return_home": False}
    )
    stations = _crossing(sc)
    # flown straight from their starts, the two legs come within this of each other
    a0, a1 = np.array([150.0, 1300.0]), np.array([150.0, 1000.0])
    d0, d1 = stations[0, :2] - a0, stations[1, :2] - a1
    t = np.linspace(0, 1, 2001)[:, None]
    straight = np.min(np.linalg.norm((a0 + t * d0) - (a1 + t * d1), axis=1))
    assert straight < sc.avoidance.d_min_m  # the course is a collision one

    def planner(j: int):
        p = make_planner(sc.avoidance.planner, PlannerConfig.from_scenario(sc))
        p.reset(100 + j)
        return p

    spec = episode_spec(sc, dynamics="jsbsim", service_point=stations[0], mission=True)
    fleet = Fleet(sc, stations, planner, spec.max_steps)
    r = fly(spec, planner(0), engine_steps=[Energy(), fleet])
    member = fleet.members[0]
    assert r.outcome is Outcome.COMPLETED, r.summary.get("failure")
    assert member.outcome is Outcome.COMPLETED
    assert r.min_separation_m >= sc.avoidance.d_min_m
    assert member.ep.min_separation_m >= sc.avoidance.d_min_m
    assert [e["id"] for e in r.summary["fleet"]] == ["ownship-0", "ownship-1"]


# ------------------------------------------------------------------------------ whole run
@pytest.fixture(scope="module")
def fleet_run(tmp_path_factory) -> Path:
    out = tmp_path_factory.mktemp("fleet")
    assert main(["run", str(FLEET), "--out", str(out), "--force"]) == 0
    return out


def test_fleet_run_flies_every_member_and_reports_each(fleet_run: Path) -> None:
    summary = json.loads((fleet_run / "summary.json").read_text())
    sc = load_scenario(FLEET)
    fleet = summary["fleet"]
    assert [u["id"] for u in fleet] == [f"ownship-{i}" for i in range(sc.fleet.size)]
    assert summary["outcome"] == "completed"
    served = sorted(k for u in fleet for k in u["users_served"])
    assert served == list(range(sc.comms.users.k))  # each user served by one UAV
    for u in fleet:
        assert u["outcome"] == "completed"
        assert u["min_separation_m"] >= sc.avoidance.d_min_m
        assert u["energy_wh"] > 0 and u["delivered_bits"] > 0
    ids = {row["id"] for row in csv.DictReader((fleet_run / "trajectory.csv").open())}
    assert {u["id"] for u in fleet} <= ids and "ownship" not in ids


def test_fleet_delivered_bits_are_recomputed_from_service_csv(fleet_run: Path) -> None:
    summary = json.loads((fleet_run / "summary.json").read_text())
    dt = 1.0 / load_scenario(FLEET).dynamics.trajectory_hz
    with (fleet_run / "service.csv").open() as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == SERVICE_COLUMNS
        bits: dict[int, float] = {}
        for row in reader:
            uav = int(row["uav"])
            bits[uav] = bits.get(uav, 0.0) + float(row["rate_bps"]) * dt
    for n, u in enumerate(summary["fleet"]):
        assert bits[n] == pytest.approx(u["delivered_bits"], rel=0.01)
        # each row's user is one this UAV serves
    with (fleet_run / "service.csv").open() as f:
        for row in csv.DictReader(f):
            assert int(row["user"]) in summary["fleet"][int(row["uav"])]["users_served"]
    assert summary["mission"]["delivered_bits"] == pytest.approx(sum(bits.values()), rel=0.01)


def test_fleet_yaml_stations_are_kept_apart_for_orbits_and_nmac() -> None:
    """fleet.yaml seed 3 placed two stations 286 m apart at one height (orbits of 106 m:
    member 0 came within 144 m of a member); each pair is now 2r + NMAC apart or a layer."""
    from uavxai.dynamics.orbit import scenario_orbit_radius
    from uavxai.service.stage import plan_service
    from uavxai.sim.fleet import HEIGHT_HOLD_M, fleet_stations, orbit_separation

    sc = load_scenario(FLEET).with_seed(3)
    sep = orbit_separation(sc)
    r, nmac = scenario_orbit_radius(sc), sc.avoidance.nmac
    assert sep.horizontal_m == pytest.approx(2 * r + nmac.horizontal_m)
    assert sep.vertical_m == pytest.approx(nmac.vertical_m + 2 * HEIGHT_HOLD_M)
    stations = fleet_stations(sc, plan_service(sc).users).positions
    for i in range(3):
        for j in range(i + 1, 3):
            d = stations[i] - stations[j]
            horizontal, vertical = math.hypot(d[0], d[1]), abs(d[2])
            assert horizontal >= sep.horizontal_m or vertical >= sep.vertical_m, (i, j)
