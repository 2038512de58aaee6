"""The delivered service of a mission, recomputed from its files with the channel equations."""

from __future__ import annotations

import csv
import json
import math
from collections import defaultdict
from pathlib import Path

import numpy as np
import yaml

from uavxai.cli import main
from uavxai.comms.channel import ENVIRONMENTS
from uavxai.comms.delivery import SERVICE_COLUMNS, USERS_COLUMNS

C = 299_792_458.0
MISSION = {
    "name": "served",
    "seed": 5,
    "intruders": {"count": 3, "flow": "none"},
    "comms": {"fading": "none", "access": "shared", "environment": "urban",
              "users": {"mobility": {"model": "random_waypoint"}}},
    # grid's exact hover optimum: fast, and every re-plan of the walking users runs it again
    "service": {"planner": "grid", "steps": 10, "platform": "hover"},
    "mission": {"service_s": 40, "return_home": False},
    "log": {"rerun": False},
}  # fmt: skip


def _rates(uav, users, power, sc) -> np.ndarray:
    """Eqs (1)-(5) of the paper, written out: distance, LoS probability on the elevation in
    degrees, mean path loss, gain, SINR with the shared band's interference, rate."""
    a, b, eta_los, eta_nlos = ENVIRONMENTS[sc["environment"]]
    d = np.linalg.norm(users - uav, axis=1)
    theta = np.degrees(np.arcsin((uav[2] - users[:, 2]) / d))
    p_los = 1.0 / (1.0 + a * np.exp(-b * (theta - a)))
    fspl = 20 * np.log10(4 * math.pi * sc["carrier_ghz"] * 1e9 * d / C)
    gain = 10 ** (-(fspl + p_los * eta_los + (1 - p_los) * eta_nlos) / 10)
    noise = 10 ** ((sc["noise_dbm"] - 30) / 10)
    interference = gain * (power.sum() - power)
    return sc["bandwidth_hz"] * np.log2(1 + gain * power / (interference + noise))


def test_delivered_bits_recomputed_from_users_trajectory_and_service_files(
    tmp_path: Path, capfd
) -> None:
    path = tmp_path / "m.yaml"
    path.write_text(yaml.safe_dump(MISSION))
    out = tmp_path / "run"
    assert main(["run", str(path), "--out", str(out)]) == 0
    printed = " ".join(capfd.readouterr().err.split())
    for words in ("completed", "delivered", "Mbit", "QoS met", "lost to avoidance", "energy"):
        assert words in printed, words
    summary = json.loads((out / "summary.json").read_text())
    assert summary["outcome"] == "completed"
    sc = {"environment": "urban", "carrier_ghz": 2.0, "noise_dbm": -100.0, "bandwidth_hz": 1e6}
    own = {}
    with (out / "trajectory.csv").open() as f:
        for r in csv.DictReader(f):
            if r["id"] == "ownship":
                own[f"{float(r['t']):.3f}"] = np.array([float(r[k]) for k in "xyh"])
    users = defaultdict(dict)
    with (out / "users.csv").open() as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == USERS_COLUMNS
        for r in reader:
            users[r["t"]][int(r["user"])] = (float(r["x"]), float(r["y"]), 0.0)
    power = defaultdict(dict)
    with (out / "service.csv").open() as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == SERVICE_COLUMNS
        for r in reader:
            power[r["t"]][int(r["user"])] = float(r["power_w"])
    assert len(power) == 400  # 40 s on station at 10 Hz
    moved = {t for t in users if users[t] != users["0.100"]}
    assert moved  # the users walked
    dt, bits = 0.1, 0.0
    for t, p in power.items():
        k = sorted(p)
        rates = _rates(own[t], np.array([users[t][i] for i in k]), np.array([p[i] for i in k]), sc)
        bits += float(rates.sum()) * dt
    reported = summary["mission"]["delivered_bits"]
    assert abs(bits - reported) <= 0.01 * reported
    assert 0.0 <= summary["mission"]["qos_user_seconds_share"] <= 1.0
    assert 0.0 < summary["mission"]["jain_fairness"] <= 1.0


def test_walking_users_make_the_mission_replan_and_move_its_orbit() -> None:
    """Users walk; every service.replan_s the service point is planned again for where they
    are, and the orbit moves there (kinematic world, the shipped zero-shot D3QN)."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.comms.channel import Channel
    from uavxai.scenario import default_scenario
    from uavxai.service.stage import plan_service
    from uavxai.sim.build import fly
    from uavxai.sim.run_flight import _replanner
    from uavxai.sim.spec import episode_spec
    from uavxai.sim.steps import Service

    sc = default_scenario(
        "walk",
        seed=3,
        intruders={"count": 0},
        comms={"access": "ofdma", "users": {"mobility": {"model": "random_waypoint",
                                                         "speed_mps": [1.5, 2.0]}}},
        service={"replan_s": 20},
        mission={"service_s": 90, "return_home": False},
    )  # fmt: skip
    plan = plan_service(sc)
    station = tuple(float(v) for v in plan.service_point)
    service = Service(sc, Channel.from_scenario(sc, users=plan.users), plan.power_w, None,
                      replan=_replanner(sc))  # fmt: skip
    planner = make_planner("mcts_fast", PlannerConfig.from_scenario(sc))
    r = fly(
        episode_spec(sc, goal=station, dynamics="kinematic", mission=True),
        planner,
        engine_steps=[service],
    )
    points = r.summary["mission"]["service_points"]
    assert r.outcome.value == "completed"
    assert len(points) >= 4  # the first plan, then every 20 s on station
    moved = {tuple(p[1:]) for p in points}
    assert len(moved) >= 2  # the users walked far enough to move the point
    assert r.summary["mission"]["delivered_bits"] > 0
