"""Cost of recording a run with rerun: 21 aircraft at 10 Hz of sim time plus 1 decision/s.

Prints the wall time spent in RunRecorder per simulated second (and per frame / decision),
the .rrd size, and, for scale, the same traffic logged the naive way (one rr.log per aircraft
per frame). Then the same run recorded as a mission: the map on, K users with rates every
sample, phase and orbit every sample, tracks every decision. Inputs are generated up front so
only recording is timed.

    .venv/bin/python benchmarks/performance/bench_recording.py [--duration 400] [--intruders 20]
        [--users 20]
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path

import numpy as np
import rerun as rr

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.recording import synthetic
from uavxai.recording.recorder import RunRecorder

RATE_HZ = 10.0
JSBSIM_STEP_S = 15e-6  # one FGFDMExec.run() of a light aircraft (DEPENDENCY-NOTES)
JSBSIM_HZ = 120.0


def inputs(n_intruders: int, duration_s: float):
    states = list(synthetic.traffic(n_intruders, duration_s, rate_hz=RATE_HZ))
    every = int(RATE_HZ)  # one decision per simulated second
    decisions = {
        i: synthetic.decision(s, i // every) for i, s in enumerate(states) if i % every == 0
    }
    return states, decisions


def record(path: Path, states, decisions, n_intruders: int) -> dict[str, float]:
    ids = [f"intruder-{i + 1}" for i in range(n_intruders)]
    spent = {"traffic": 0.0, "decision": 0.0, "setup+close": 0.0}
    t0 = time.perf_counter()
    rec = RunRecorder(path, recording_id="bench")
    rec.log_setup(synthetic.BOUNDS, synthetic.users(), synthetic.GOAL, None, ids, synthetic.GOAL)
    spent["setup+close"] += time.perf_counter() - t0
    for i, state in enumerate(states):
        t0 = time.perf_counter()
        rec.log_traffic(state)
        t1 = time.perf_counter()
        spent["traffic"] += t1 - t0
        if i in decisions:
            synthetic.log_decision(rec, i // int(RATE_HZ), state, decisions[i], ids)
            spent["decision"] += time.perf_counter() - t1
    t0 = time.perf_counter()
    rec.close()
    spent["setup+close"] += time.perf_counter() - t0
    return spent


def record_mission(path: Path, states, decisions, n_intruders: int, k_users: int) -> dict:
    """The run as a mission: everything ``record`` logs plus the mission calls, map on."""
    ids = [f"intruder-{i + 1}" for i in range(n_intruders)]
    rng = np.random.default_rng(1)
    users = synthetic.users(k_users)
    walk = rng.normal(0.0, 1.0, users.shape) * [1.0, 1.0, 0.0] / RATE_HZ
    qos = 2.0e6
    spent = {"traffic": 0.0, "decision": 0.0, "mission/sample": 0.0, "setup+close": 0.0}
    t0 = time.perf_counter()
    rec = RunRecorder(path, recording_id="bench-mission")
    # The mission's batches go out inside whichever call crosses the flush period: time them
    # apart (a part of "traffic" / "mission/sample" below, not in addition).
    flush_s = [0.0]
    mission_flush = rec._mission.flush

    def timed_flush() -> None:
        f0 = time.perf_counter()
        mission_flush()
        flush_s[0] += time.perf_counter() - f0

    rec._mission.flush = timed_flush
    origin = LocalFrame(47.3977, 8.5456, 400.0)
    rec.log_setup(synthetic.BOUNDS, users, synthetic.GOAL, None, ids, synthetic.GOAL, origin)
    spent["setup+close"] += time.perf_counter() - t0
    for i, state in enumerate(states):
        users = users + walk
        d2 = np.sum((users - state.pos[0]) ** 2, axis=1)
        rate = 1e6 * np.log2(1.0 + 1e6 / d2)
        t0 = time.perf_counter()
        rec.log_traffic(state)
        t1 = time.perf_counter()
        spent["traffic"] += t1 - t0
        rec.log_users(state.t, users, rate, qos, state.pos[0])
        rec.log_phase(state.t, "on_station" if (state.t // 60) % 2 else "transit")
        rec.log_orbit(state.t, synthetic.GOAL, 250.0 + 50.0 * ((state.t // 60) % 2))
        if i % int(RATE_HZ * 30) == 0:
            rec.log_service_point(state.t, synthetic.GOAL + [i * 0.01, 0.0, 0.0])
        t2 = time.perf_counter()
        spent["mission/sample"] += t2 - t1
        if i in decisions:
            k = i // int(RATE_HZ)
            synthetic.log_decision(rec, k, state, decisions[i], ids, float(rate.sum()))
            rec.log_tracks(state.t, ids, state.pos[1:], np.full(n_intruders, 15.0))
            spent["decision"] += time.perf_counter() - t2
    t0 = time.perf_counter()
    rec.close()
    spent["setup+close"] += time.perf_counter() - t0
    spent["(of which mission flushes)"] = flush_s[0]
    return spent


def record_naively(path: Path, states) -> float:
    """One rr.log per aircraft per frame, as a straightforward logger would."""
    stream = rr.RecordingStream("uavxai-naive")
    stream.save(path)
    t0 = time.perf_counter()
    for state in states:
        stream.set_time("sim_time", duration=state.t)
        for j in range(state.n):
            stream.log(f"world/aircraft/{j}", rr.Transform3D(translation=state.pos[j]))
    stream.flush()
    stream.disconnect()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=400.0, help="simulated seconds")
    ap.add_argument("--intruders", type=int, default=20)
    ap.add_argument("--naive-duration", type=float, default=60.0)
    ap.add_argument("--users", type=int, default=20, help="users in the mission recording")
    a = ap.parse_args()

    states, decisions = inputs(a.intruders, a.duration)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.rrd"
        spent = record(path, states, decisions, a.intruders)
        size = path.stat().st_size
        naive_states = states[: int(a.naive_duration * RATE_HZ) + 1]
        naive = record_naively(Path(tmp) / "naive.rrd", naive_states)
        mission_path = Path(tmp) / "mission.rrd"
        mission = record_mission(mission_path, states, decisions, a.intruders, a.users)
        mission_size = mission_path.stat().st_size

    total = sum(spent.values())
    per_sim_s = total / a.duration
    jsbsim = (a.intruders + 1) * JSBSIM_HZ * JSBSIM_STEP_S
    print(
        f"run: {a.duration:.0f} s simulated, {a.intruders + 1} aircraft at {RATE_HZ:.0f} Hz "
        f"({len(states)} frames), {len(decisions)} decisions"
    )
    print(f"recording wall time      {total * 1e3:8.1f} ms total")
    print(f"  per simulated second   {per_sim_s * 1e3:8.2f} ms")
    print(
        f"  log_traffic per frame  {spent['traffic'] / len(states) * 1e6:8.1f} us (incl. flushes)"
    )
    print(f"  decision+metrics each  {spent['decision'] / len(decisions) * 1e3:8.2f} ms")
    print(f"  setup + close          {spent['setup+close'] * 1e3:8.1f} ms")
    print(
        f".rrd size                {size / 1e6:8.2f} MB "
        f"({size / a.duration / 1e3:.1f} kB per sim s)"
    )
    print(
        f"for scale: JSBSim alone  {jsbsim * 1e3:8.2f} ms per sim s "
        f"({a.intruders + 1} aircraft x {JSBSIM_HZ:.0f} Hz x {JSBSIM_STEP_S * 1e6:.0f} us)"
    )
    print(f"  recording / JSBSim     {per_sim_s / jsbsim * 100:8.1f} %")
    naive_per_s = naive / a.naive_duration
    print(
        f"naive rr.log per frame   {naive_per_s * 1e3:8.2f} ms per sim s "
        f"(transforms only, {len(naive_states)} frames)"
    )
    m_total = sum(v for k, v in mission.items() if not k.startswith("("))
    print(f"mission recording ({a.users} users every sample, map on, tracks every decision)")
    print(f"  per simulated second   {m_total / a.duration * 1e3:8.2f} ms")
    for name, s in mission.items():
        print(f"    {name:<26} {s / a.duration * 1e3:8.2f} ms per sim s")
    print(
        f"  .rrd size              {mission_size / 1e6:8.2f} MB "
        f"({mission_size / a.duration / 1e3:.1f} kB per sim s)"
    )
    print(f"  recording / JSBSim     {m_total / a.duration / jsbsim * 100:8.1f} %")


if __name__ == "__main__":
    main()
