"""End to end: `uavxai run` flies JSBSim, sends real MAVLink bytes over loopback, writes a real
.rrd, and everything it reports agrees with itself."""

from __future__ import annotations

import csv
import json
import os
import socket
import threading
import time
from collections import defaultdict
from pathlib import Path

os.environ.setdefault("MAVLINK20", "1")

import numpy as np
import pytest
import yaml
from pymavlink import mavutil

from uavxai.cli import main
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.scenario import load_scenario
from uavxai.sim.observers import TRAJECTORY_FIELDS

SMALL = {
    "name": "small",
    "seed": 7,
    "ownship": {
        "start": {"x": 300, "y": 1000, "h": 120, "heading_deg": 90, "speed_mps": 20},
        "goal": [1700, 1000, 120],
    },
    "intruders": {
        "list": [
            {"x": 1100, "y": 1000, "h": 120, "heading_deg": 270, "speed_mps": 20},
            {"x": 900, "y": 600, "h": 125, "heading_deg": 10, "speed_mps": 18},
            {"x": 1500, "y": 1400, "h": 118, "heading_deg": 200, "speed_mps": 22},
        ],
        "flow": "none",  # these three only: the ADS-B check below counts them
    },
    "avoidance": {"max_steps": 25, "mcts": {"simulations": 60, "depth": 3}},
}


def free_udp_port() -> int:
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as s:
        s.bind(("127.0.0.1", 0))
        return s.getsockname()[1]


class Listener(threading.Thread):
    """A pymavlink ground-side socket collecting everything the vehicle sends."""

    def __init__(self, port: int) -> None:
        super().__init__(daemon=True)
        self.conn = mavutil.mavlink_connection(f"udpin:127.0.0.1:{port}", source_system=255)
        self.conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
        self.msgs: dict[str, list] = defaultdict(list)
        self.stop = threading.Event()

    def run(self) -> None:
        while not self.stop.is_set():
            m = self.conn.recv_match(blocking=True, timeout=0.2)
            if m is not None:
                self.msgs[m.get_type()].append(m)

    def close(self) -> None:
        self.stop.set()
        self.join(timeout=2)
        self.conn.close()


@pytest.fixture(scope="module")
def flown(tmp_path_factory: pytest.TempPathFactory):
    tmp = tmp_path_factory.mktemp("run")
    scenario = tmp / "small.yaml"
    scenario.write_text(yaml.safe_dump(SMALL))
    port = free_udp_port()
    listener = Listener(port)
    listener.start()
    out = tmp / "out"
    try:
        rc = main(
            ["run", str(scenario), "--out", str(out), "--mavlink", f"udpout:127.0.0.1:{port}"]
        )
        time.sleep(0.5)
    finally:
        listener.close()
    assert rc == 0
    return load_scenario(scenario), out, listener.msgs


def read_trajectory(out: Path) -> dict[str, np.ndarray]:
    rows: dict[str, list] = defaultdict(list)
    with (out / "trajectory.csv").open() as f:
        reader = csv.DictReader(f)
        assert tuple(reader.fieldnames or ()) == TRAJECTORY_FIELDS  # README: test_csv_columns.py
        for r in reader:
            rows[r["id"]].append([float(r[k]) for k in ("t", "x", "y", "h", "phi", "psi")])
    return {k: np.asarray(v) for k, v in rows.items()}


def test_outputs_exist_and_agree(flown) -> None:
    sc, out, _ = flown
    summary = json.loads((out / "summary.json").read_text())
    for key in (
        "scenario",
        "seed",
        "outcome",
        "min_separation_m",
        "steps",
        "flight_time_s",
        "service_point",
        "power_w",
        "sinr_db",
        "rate_bps",
        "sum_rate_bps",
        "qos_satisfied",
        "decision_ms",
        "sim_realtime_factor",
        "versions",
        "trust",
    ):
        assert key in summary, key
    assert summary["outcome"] in ("goal", "collision", "timeout", "out_of_bounds")
    assert summary["seed"] == 7 and len(summary["power_w"]) == sc.comms.users.k
    decisions = [json.loads(line) for line in (out / "decisions.jsonl").read_text().splitlines()]
    assert len(decisions) == summary["steps"] >= 1
    for d in decisions:
        assert {"t", "state", "action", "children", "explanation", "ms"} <= set(d)
        assert len(d["children"]) == 9 and d["explanation"]
    traj = read_trajectory(out)
    assert set(traj) == {"ownship", "intruder-1", "intruder-2", "intruder-3"}
    own = traj["ownship"]
    assert np.all(np.diff(own[:, 0]) > 0) and np.median(np.diff(own[:, 0])) <= 0.1 + 1e-9
    # The separation the summary reports is what the trajectory shows (or less: the summary
    # also counts closest approach between samples).
    seps = [
        np.min(np.linalg.norm(traj[i][:, 1:4] - own[:, 1:4], axis=1))
        for i in traj
        if i != "ownship"
    ]
    assert summary["min_separation_m"] <= min(seps) + 1e-6
    assert summary["min_separation_m"] >= min(seps) - 25.0


def test_mavlink_telemetry_matches_trajectory(flown) -> None:
    sc, out, msgs = flown
    for kind in ("HEARTBEAT", "GLOBAL_POSITION_INT", "ATTITUDE", "ADSB_VEHICLE", "VFR_HUD"):
        assert msgs[kind], f"no {kind} received"
    hb = msgs["HEARTBEAT"][0]
    assert hb.type == mavutil.mavlink.MAV_TYPE_FIXED_WING
    assert hb.autopilot == mavutil.mavlink.MAV_AUTOPILOT_ARDUPILOTMEGA
    assert mavutil.mode_string_v10(hb) == "AUTO"  # the scenario's own flight
    assert hb.get_srcSystem() == sc.bridge.system_id
    frame = LocalFrame.from_origin(sc.world.origin)
    traj = read_trajectory(out)
    own = traj["ownship"]
    by_ms = {round(r[0] * 1000): r for r in own}
    matched = 0
    for m in msgs["GLOBAL_POSITION_INT"]:
        row = by_ms.get(m.time_boot_ms)
        if row is None:
            continue
        x, y, h = frame.to_local(m.lat * 1e-7, m.lon * 1e-7, m.alt * 1e-3)
        assert np.linalg.norm([x - row[1], y - row[2], h - row[3]]) < 1.0
        assert abs(m.relative_alt * 1e-3 - row[3]) < 1.0
        matched += 1
    assert matched >= 0.8 * len(msgs["GLOBAL_POSITION_INT"]) and matched > 20
    att_matched = 0
    for m in msgs["ATTITUDE"]:
        row = by_ms.get(m.time_boot_ms)
        if row is not None:
            assert abs(m.roll - row[4]) < 1e-3
            att_matched += 1
    assert att_matched > 20
    # The traffic the ground station sees is the ADS-B receiver's (surveillance.model: adsb,
    # NACp 10: 95 % of horizontal errors within 10 m), not the truth.
    icao_seen, errors = set(), []
    for m in msgs["ADSB_VEHICLE"]:
        icao_seen.add(m.ICAO_address)
        x, y, h = frame.to_local(m.lat * 1e-7, m.lon * 1e-7, m.altitude * 1e-3)
        rows = traj[f"intruder-{m.ICAO_address - 0xF00000}"]
        errors.append(float(np.min(np.linalg.norm(rows[:, 1:3] - [x, y], axis=1))))
    assert len(icao_seen) == 3
    assert 0.5 < float(np.median(errors)) < 10.0 and max(errors) < 30.0


def test_recording_read_back(flown) -> None:
    from rerun.chunk import RrdReader

    _, out, _ = flown
    rrd = out / "run.rrd"
    assert rrd.stat().st_size > 10_000
    chunks = RrdReader(str(rrd)).stream().to_chunks()
    paths = {c.entity_path for c in chunks}
    for p in (
        "/world/ownship",
        "/world/ownship/trail",
        "/world/intruders/1",
        "/world/users",
        "/world/service_point",
        "/world/plan",
        "/xai/tree",
        "/xai/explanation",
        "/metrics/min_separation_m",
        "/metrics/bank_deg",
        "/metrics/sum_rate_bps",
    ):
        assert p in paths, (p, sorted(paths))
    n_decisions = len((out / "decisions.jsonl").read_text().splitlines())
    for entity in ("/xai/tree", "/xai/explanation"):
        seen: set[int] = set()
        for c in chunks:
            if c.entity_path == entity:
                seen.update(c.to_record_batch().column("decision").to_pylist())
        assert seen == set(range(n_decisions)), entity


def test_explain_the_run(flown, capsys: pytest.CaptureFixture[str]) -> None:
    _, out, _ = flown
    assert main(["explain", str(out), "--decision", "0"]) == 0
    text = capsys.readouterr().out
    assert len(text.strip()) > 20
    assert main(["explain", str(out), "--decision", "9999"]) == 2


def test_same_seed_same_numbers(flown, tmp_path: Path) -> None:
    """A second run of the same scenario and seed gives the same trajectory, bit for bit."""
    sc, out, _ = flown
    scenario = tmp_path / "small.yaml"
    scenario.write_text(yaml.safe_dump(SMALL))
    again = tmp_path / "again"
    assert main(["run", str(scenario), "--out", str(again)]) == 0
    a = (out / "trajectory.csv").read_text()
    b = (again / "trajectory.csv").read_text()
    assert a == b


def test_realtime_pacing(tmp_path: Path) -> None:
    """--realtime X never lets simulated time run ahead of X times the wall clock."""
    scenario = tmp_path / "paced.yaml"
    scenario.write_text(
        yaml.safe_dump({**SMALL, "avoidance": {**SMALL["avoidance"], "max_steps": 6}})
    )
    out = tmp_path / "paced"
    assert main(["run", str(scenario), "--out", str(out), "--realtime", "8"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert summary["flight_time_s"] == pytest.approx(6.0)
    assert summary["sim_realtime_factor"] <= 8.0 + 1e-6


def test_several_episodes(tmp_path: Path) -> None:
    scenario = tmp_path / "multi.yaml"
    scenario.write_text(
        yaml.safe_dump({**SMALL, "avoidance": {**SMALL["avoidance"], "max_steps": 4}})
    )
    out = tmp_path / "multi"
    assert main(["run", str(scenario), "--out", str(out), "--episodes", "2"]) == 0
    summary = json.loads((out / "summary.json").read_text())
    assert [e["seed"] for e in summary["episodes"]] == [7, 8]
    assert summary["episodes_run"] == 2 and 0 <= summary["goal_rate"] <= 1
    for i in range(2):
        assert (out / f"episode-{i:03d}" / "trajectory.csv").is_file()
        assert (out / f"episode-{i:03d}" / "run.rrd").is_file()


def test_the_run_writes_its_link_to_a_tlog_a_ground_station_can_replay(flown) -> None:
    """`uavxai run` (JSBSim, a real link): RUN/link.tlog, read back with pymavlink, holds one
    stamped frame for every frame the bridge counted, in and out, in time order."""
    sc, out, msgs = flown
    counters = json.loads((out / "summary.json").read_text())["bridge"]
    log = mavutil.mavlink_connection(str(out / "link.tlog"))
    n, stamps, kinds = 0, [], defaultdict(int)
    while (m := log.recv_match()) is not None:
        assert m.get_type() != "BAD_DATA"
        n += 1
        kinds[m.get_type()] += 1
        stamps.append(m._timestamp)
    log.close()
    assert n == counters["messages_in"] + counters["messages_out"]
    assert {"HEARTBEAT", "SET_ATTITUDE_TARGET", "GLOBAL_POSITION_INT", "ADSB_VEHICLE"} <= set(kinds)
    assert stamps == sorted(stamps)
    # what the listener heard on loopback is what the tlog says was sent
    assert 0.9 * kinds["HEARTBEAT"] <= len(msgs["HEARTBEAT"]) <= kinds["HEARTBEAT"]


def test_sys_status_reports_the_battery_as_it_drains(flown) -> None:
    """SYS_STATUS voltage and current come from the battery model (not a constant nominal
    22.2 V): the voltage of the 6S pack falls with its charge, the current follows the load."""
    _, _, msgs = flown
    status = msgs["SYS_STATUS"]
    assert len(status) > 50
    volts = np.array([m.voltage_battery for m in status]) / 1000.0
    amps = np.array([m.current_battery for m in status]) / 100.0
    assert volts.min() > 6 * 3.7 and volts.max() <= 6 * 4.2 + 1e-9
    assert len(set(volts.round(3))) > 5  # not a constant
    assert volts[:10].mean() > volts[-10:].mean()  # drains
    assert 1.0 < amps.mean() < 60.0 and amps.std() > 0
