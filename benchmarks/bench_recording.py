"""Cost of recording a run with rerun: 21 aircraft at 10 Hz of sim time plus 1 decision/s.

Prints the wall time spent in RunRecorder per simulated second (and per frame / decision),
the .rrd size, and, for scale, the same traffic logged the naive way (one rr.log per aircraft
per frame). Inputs are generated up front so only recording is timed.

    .venv/bin/python benchmarks/bench_recording.py [--duration 400] [--intruders 20]
"""

from __future__ import annotations

import argparse
import math
import sys
import tempfile
import time
from pathlib import Path

import rerun as rr

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "tests"))  # test fixtures
import synthetic  # noqa: E402

from uavxai.recording.recorder import RunRecorder  # noqa: E402

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
            d = decisions[i]
            rec.log_decision(i // int(RATE_HZ), state.t, d, ids)
            rec.log_metrics(
                state.t,
                sum_rate_bps=2.3e7,
                min_separation_m=state.min_separation(),
                bank_deg=math.degrees(state.att[0, 0]),
                airspeed_mps=float(state.airspeed[0]),
                decision_ms=d.ms,
            )
            spent["decision"] += time.perf_counter() - t1
    t0 = time.perf_counter()
    rec.close()
    spent["setup+close"] += time.perf_counter() - t0
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
    a = ap.parse_args()

    states, decisions = inputs(a.intruders, a.duration)
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.rrd"
        spent = record(path, states, decisions, a.intruders)
        size = path.stat().st_size
        naive_states = states[: int(a.naive_duration * RATE_HZ) + 1]
        naive = record_naively(Path(tmp) / "naive.rrd", naive_states)

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


if __name__ == "__main__":
    main()
