"""`uavxai run`: the whole co-simulation, one seeded episode at a time.

scenario -> service point (D3QN) -> JSBSim world -> avoidance planner -> MAVLink bytes ->
bridge -> JSBSim autopilot -> recordings. The planner never touches the aircraft: its decision
is encoded as MAVLink 2 messages, decoded by the bridge, and only the bridge writes the
autopilot's setpoints — the same path an external peer on `--mavlink` uses.
"""

from __future__ import annotations

import csv
import json
import logging
import math
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console
from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

from uavxai import __version__
from uavxai.avoidance.types import Decision, Intruder, Ownship
from uavxai.dynamics.state import TrafficState
from uavxai.scenario import Scenario

log = logging.getLogger(__name__)
console = Console(stderr=True, soft_wrap=True)

TRAJECTORY_FIELDS = ("t", "id", "x", "y", "h", "vx", "vy", "vh", "phi", "theta", "psi", "airspeed")


@dataclass
class EpisodeOutcome:
    outcome: str
    steps: int
    flight_time_s: float
    min_separation_m: float
    decision_ms: list[float]
    separation_errors_m: list[float]
    wall_s: float
    failure: str | None = None
    bridge_counters: dict[str, int] = field(default_factory=dict)


def _stats(values: list[float], keys=("mean", "p50", "p95", "max")) -> dict[str, float | None]:
    if not values:
        return dict.fromkeys(keys)
    a = np.asarray(values, dtype=float)
    table = {
        "mean": float(a.mean()),
        "p50": float(np.percentile(a, 50)),
        "p95": float(np.percentile(a, 95)),
        "max": float(a.max()),
    }
    return {k: table[k] for k in keys}


def _closest_approach(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Minimum ownship-intruder distance over one logging interval, both moving linearly
    between samples: catches a pass-through that the 10 Hz samples alone would miss."""
    d0 = q0 - p0  # (N, 3) relative positions at the start
    dv = (q1 - p1) - d0  # change over the interval
    denom = np.einsum("ij,ij->i", dv, dv)
    s = np.clip(-np.einsum("ij,ij->i", d0, dv) / np.where(denom > 0, denom, 1.0), 0.0, 1.0)
    closest = d0 + s[:, None] * dv
    return float(np.min(np.linalg.norm(closest, axis=1))) if len(d0) else math.inf


def planner_inputs(state: TrafficState, bank_cmd: float) -> tuple[Ownship, list[Intruder]]:
    """What the planner sees: the ownship's kinematic state and every intruder's track."""
    own = Ownship(
        x=float(state.pos[0, 0]),
        y=float(state.pos[0, 1]),
        h=float(state.pos[0, 2]),
        speed=float(state.airspeed[0]),
        heading=float(state.att[0, 2]),
        bank=float(bank_cmd),
        phi=float(state.att[0, 0]),
    )
    intruders = [
        Intruder(
            id=state.ids[i],
            x=float(state.pos[i, 0]),
            y=float(state.pos[i, 1]),
            h=float(state.pos[i, 2]),
            vx=float(state.vel[i, 0]),
            vy=float(state.vel[i, 1]),
            vh=float(state.vel[i, 2]),
        )
        for i in range(1, state.n)
    ]
    return own, intruders


def _trajectory_rows(state: TrafficState):
    for i, ident in enumerate(state.ids):
        yield (
            round(state.t, 4),
            ident,
            *(round(float(v), 3) for v in state.pos[i]),
            *(round(float(v), 3) for v in state.vel[i]),
            *(round(float(v), 5) for v in state.att[i]),
            round(float(state.airspeed[i]), 3),
        )


def run_episode(
    scenario: Scenario,
    out: Path,
    *,
    rerun_file: Path | None = None,
    spawn: bool = False,
    mavlink: str | None = None,
    realtime: float | None = None,
    service=None,
    record: bool | None = None,
    progress: Progress | None = None,
) -> dict:
    """Fly one seeded episode; write trajectory.csv, decisions.jsonl and run.rrd into `out`;
    return the episode's summary (SPEC §4)."""
    from uavxai.avoidance import PlannerConfig, make_planner
    from uavxai.bridges.bridge import MavlinkBridge
    from uavxai.bridges.protocol import CommandEncoder
    from uavxai.comms.channel import Channel
    from uavxai.dynamics.geodesy import LocalFrame
    from uavxai.dynamics.world import JSBSimWorld
    from uavxai.service.stage import plan_service
    from uavxai.xai.explain import decision_record

    sc = scenario
    av = sc.avoidance
    service = service if service is not None else plan_service(sc)
    # The service point is the goal unless the scenario names one explicitly.
    goal = np.asarray(
        sc.ownship.goal if sc.ownship.goal is not None else service.service_point, dtype=float
    )

    # The live sum-rate metric: the service power allocation served from where the UAV is now,
    # on the mean channel (no fading, so the curve shows geometry, not noise).
    channel = Channel.from_scenario(sc, users=service.users)
    power_w = np.asarray(service.power_w, dtype=float)
    throughput_bits = 0.0

    world = JSBSimWorld(sc, seed=sc.seed)
    frame = LocalFrame.from_origin(sc.world.origin)
    start = sc.ownship.start
    key = bytes.fromhex(sc.bridge.signing_key_hex) if sc.bridge.signing_key_hex else None
    link = mavlink if mavlink is not None else sc.bridge.mavlink
    config = PlannerConfig.from_scenario(sc)
    planner = make_planner(av.planner, config, checkpoint=av.checkpoint)
    params = {
        "UAVX_DMIN_M": av.d_min_m,
        "UAVX_SIMS": float(av.mcts.simulations),
        "UAVX_DEPTH": float(av.mcts.depth),
        "UAVX_C": av.mcts.c,
        "UAVX_HOLD_S": av.mcts.action_hold_s,
        "UAVX_BANK_LIM": av.bank_limit_deg,
        "UAVX_PERIOD_S": av.decision_period_s,
        "UAVX_TIMEOUT_S": sc.bridge.command_timeout_s,
    }
    bridge = MavlinkBridge(
        sc.bridge.system_id,
        frame,
        world,
        link=link,
        signing_key=key,
        command_timeout_s=sc.bridge.command_timeout_s,
        params=params,
        home=(start.x, start.y, start.h),
    )
    encoder = CommandEncoder(sc.bridge.system_id, sc.bridge.system_id, signing_key=key)
    record = sc.log.rerun if record is None else record
    recorder = None
    state = world.state()
    intruder_ids = list(state.ids[1:])
    if record or spawn or rerun_file is not None:
        from uavxai.recording.recorder import RunRecorder

        recorder = RunRecorder(
            None if spawn else (rerun_file or out / "run.rrd"),
            spawn=spawn,
            recording_name="uavxai",
            recording_id=f"{sc.name}-seed{sc.seed}",
        )
        recorder.log_setup(
            bounds={"x": sc.world.x, "y": sc.world.y, "h": sc.world.h},
            users=service.users,
            service_point=service.service_point,
            search_path=service.visited,
            intruder_ids=intruder_ids,
            goal=goal,
        )

    world.command_ownship(alt_target_m=float(goal[2]))
    sample_dt = 1.0 / sc.dynamics.trajectory_hz
    sub_per_decision = max(1, round(av.decision_period_s / sample_dt))
    sample_dt = av.decision_period_s / sub_per_decision
    wall0 = time.perf_counter()
    outcome, failure = "timeout", None
    min_sep = state.min_separation()
    decision_ms: list[float] = []
    sep_errors: list[float] = []
    steps = 0
    task = progress.add_task(sc.name, total=av.max_steps) if progress else None

    traj_f = (out / "trajectory.csv").open("w", newline="")
    dec_f = (out / "decisions.jsonl").open("w")
    try:
        writer = csv.writer(traj_f)
        writer.writerow(TRAJECTORY_FIELDS)
        writer.writerows(_trajectory_rows(state))
        bridge.publish(state)
        while steps < av.max_steps:
            bank_cmd = world.ownship_command()["bank_cmd_rad"]
            own, intruders = planner_inputs(state, bank_cmd)
            decision: Decision = planner.plan(own, intruders, tuple(goal), step=steps)
            decision_ms.append(decision.ms)
            bridge.feed(encoder.encode(decision.bank_cmd_rad, decision.accel_mps2))
            record_json = {"step": steps, **decision_record(state.t, own, intruders, decision)}
            dec_f.write(json.dumps(record_json) + "\n")
            if recorder is not None:
                recorder.log_decision(steps, state.t, decision, intruder_ids)
            steps += 1
            flown_min = math.inf
            for _ in range(sub_per_decision):
                prev = state
                world.advance(sample_dt)
                bridge.poll()
                state = world.state()
                bridge.publish(state)
                writer.writerows(_trajectory_rows(state))
                if state.n > 1:
                    flown_min = min(
                        flown_min,
                        _closest_approach(prev.pos[0], state.pos[0], prev.pos[1:], state.pos[1:]),
                    )
                sum_rate = float(channel.evaluate(state.pos[0], power_w).sum_rate_bps)
                throughput_bits += sum_rate * sample_dt
                if recorder is not None:
                    recorder.log_traffic(state)
                    recorder.log_metrics(
                        state.t,
                        sum_rate_bps=sum_rate,
                        min_separation_m=min(state.min_separation(), 1e4),
                        bank_deg=math.degrees(float(state.att[0, 0])),
                        airspeed_mps=float(state.airspeed[0]),
                        decision_ms=decision.ms,
                    )
                if realtime:
                    lag = state.t / realtime - (time.perf_counter() - wall0)
                    if lag > 0:
                        time.sleep(lag)
                failure = world.failure()
                if failure:
                    outcome = "out_of_bounds"
                    break
                min_sep = min(min_sep, flown_min)
                if flown_min < av.d_min_m:
                    outcome = "collision"
                    break
                p = state.pos[0]
                if not sc.world.contains(float(p[0]), float(p[1]), float(p[2])):
                    outcome = "out_of_bounds"
                    break
                if float(np.linalg.norm(p - goal)) < av.goal_radius_m:
                    outcome = "goal"
                    break
            if math.isfinite(decision.predicted_min_separation_m) and math.isfinite(flown_min):
                sep_errors.append(abs(decision.predicted_min_separation_m - flown_min))
            if task is not None:
                progress.update(task, advance=1, description=f"{sc.name} t={state.t:5.0f}s")
            if outcome != "timeout" or failure:
                break
    finally:
        traj_f.close()
        dec_f.close()
        counters = dict(bridge.counters)
        bridge.close()
        world.close()
        if recorder is not None:
            recorder.close()
    wall = time.perf_counter() - wall0
    if task is not None:
        progress.update(task, completed=av.max_steps, description=f"{sc.name}: {outcome}")
    summary = {
        "scenario": sc.name,
        "seed": sc.seed,
        "outcome": outcome,
        "min_separation_m": min_sep if math.isfinite(min_sep) else None,
        "steps": steps,
        "flight_time_s": round(state.t, 3),
        "goal": [float(v) for v in goal],
        **service.to_summary(),
        "decision_ms": _stats(decision_ms),
        "throughput_in_flight_bits": throughput_bits,
        "sim_realtime_factor": state.t / wall if wall > 0 else None,
        "versions": _versions(),
        "trust": {"separation_error_m": _stats(sep_errors, ("mean", "p95", "max"))},
        "avoidance_planner": av.planner,
        "intruders": state.n - 1,
        "bridge": counters,
    }
    if failure:
        summary["failure"] = failure
    return summary


def _versions() -> dict[str, str]:
    import jsbsim
    import torch

    return {"uavxai": __version__, "jsbsim": jsbsim.__version__, "torch": torch.__version__}


def _aggregate(episodes: list[dict]) -> dict:
    n = len(episodes)
    outcomes = [e["outcome"] for e in episodes]
    seps = [e["min_separation_m"] for e in episodes if e["min_separation_m"] is not None]
    return {
        "episodes_run": n,
        "goal_rate": outcomes.count("goal") / n,
        "collision_rate": outcomes.count("collision") / n,
        "timeout_rate": outcomes.count("timeout") / n,
        "out_of_bounds_rate": outcomes.count("out_of_bounds") / n,
        "mean_steps": float(np.mean([e["steps"] for e in episodes])),
        "mean_min_separation_m": float(np.mean(seps)) if seps else None,
    }


def run_command(
    scenario: Scenario,
    *,
    out: Path,
    episodes: int = 1,
    rerun_file: Path | None = None,
    spawn: bool = False,
    mavlink: str | None = None,
    realtime: float | None = None,
) -> dict:
    """`uavxai run`: one episode writes into `out`; several write `out/episode-NNN/` each and a
    summary.json with the list and the aggregates."""
    from uavxai.service.stage import plan_service

    results = []
    with Progress(
        TextColumn("{task.description}"),
        BarColumn(),
        TextColumn("{task.completed}/{task.total}"),
        TimeElapsedColumn(),
        console=console,
        transient=False,
    ) as progress:
        for i in range(episodes):
            sc = scenario.with_seed(scenario.seed + i)
            ep_out = out if episodes == 1 else out / f"episode-{i:03d}"
            ep_out.mkdir(parents=True, exist_ok=True)
            service = plan_service(sc)
            rrd = rerun_file if (rerun_file and episodes == 1) else None
            if rerun_file and episodes > 1:
                rrd = rerun_file.with_name(f"{rerun_file.stem}-{i:03d}{rerun_file.suffix}")
            summary = run_episode(
                sc,
                ep_out,
                rerun_file=rrd,
                spawn=spawn,
                mavlink=mavlink,
                realtime=realtime,
                service=service,
                progress=progress,
            )
            (ep_out / "summary.json").write_text(json.dumps(summary, indent=2) + "\n")
            results.append(summary)
    if episodes == 1:
        final = results[0]
    else:
        final = {
            "scenario": scenario.name,
            "seed": scenario.seed,
            "episodes": results,
            **_aggregate(results),
        }
        (out / "summary.json").write_text(json.dumps(final, indent=2) + "\n")
    _report(final, out, rerun_file, spawn)
    return final


def _report(summary: dict, out: Path, rerun_file: Path | None, spawn: bool) -> None:
    eps = summary.get("episodes", [summary])
    for e in eps:
        sep = e["min_separation_m"]
        console.print(
            f"[bold]{e['scenario']}[/] seed {e['seed']}: [bold]{e['outcome']}[/] after "
            f"{e['steps']} decisions, {e['flight_time_s']:.0f} s flown; min separation "
            f"{'-' if sep is None else f'{sep:.0f} m'}; sum rate {e['sum_rate_bps'] / 1e6:.2f} "
            f"Mbit/s at the service point; decision p50 {e['decision_ms']['p50'] or 0:.1f} ms; "
            f"{e['sim_realtime_factor'] or 0:.1f}x real time"
        )
    console.print(f"outputs in {out}/ (summary.json, trajectory.csv, decisions.jsonl)")
    if not spawn:
        rrd = rerun_file or out / "run.rrd"
        if len(eps) > 1 and rerun_file is None:
            rrd = out / "episode-000" / "run.rrd"
        if rrd.exists():
            viewer = Path(sys.executable).parent / "rerun"  # installed with rerun-sdk
            viewer_cmd = str(viewer) if viewer.exists() else "rerun"
            console.print(f"recording: {rrd}  — open it with:  {viewer_cmd} {rrd}")
    first = out if len(eps) == 1 else out / "episode-000"
    console.print(f"explain a decision:  uavxai explain {first} --decision 0")
