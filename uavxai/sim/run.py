"""`uavxai run`: the whole co-simulation, one seeded episode at a time.

scenario -> service point -> JSBSim world -> avoidance planner -> MAVLink bytes -> bridge ->
JSBSim autopilot -> recordings. The planner never touches the aircraft: its decision is
encoded as MAVLink 2 messages, decoded by the bridge, and only the bridge writes the
autopilot's setpoints — the same path an external peer on ``--mavlink`` uses.
"""

from __future__ import annotations

import json
import math
import sys
from pathlib import Path

import numpy as np
from rich.console import Console

from uavxai import __version__
from uavxai.outputs import write_output
from uavxai.paths import invocation
from uavxai.processes import interrupts_deferred
from uavxai.scenario import Scenario
from uavxai.sim.build import fly
from uavxai.sim.command import MavlinkPath
from uavxai.sim.episode import EngineStep, Observer
from uavxai.sim.observers import (
    DecisionsJSONL,
    Pacing,
    ProgressBar,
    Rerun,
    SummaryJSON,
    Throughput,
    Trust,
)
from uavxai.sim.quicklook import PLOT, QuickLook
from uavxai.sim.spec import EpisodeSpec, episode_spec
from uavxai.sim.steps import Energy, Service
from uavxai.xai.explain import decisions_file

console = Console(stderr=True, soft_wrap=True)


def mavlink_path(scenario: Scenario, link: str | None, tlog: Path | None = None):
    """The command path of ``uavxai run``: encoder -> bytes -> bridge -> autopilot; ``tlog``,
    a new file that records every frame in and out (MAVProxy's .tlog)."""
    from uavxai.bridges.bridge import MavlinkBridge
    from uavxai.bridges.protocol import CommandEncoder
    from uavxai.bridges.signing import default_state_path
    from uavxai.dynamics.geodesy import LocalFrame
    from uavxai.scenario import aircraft_speed_range
    from uavxai.surveillance.emitters import TrafficCategories, emitter_type

    sc, av = scenario, scenario.avoidance
    key = bytes.fromhex(sc.bridge.signing_key_hex) if sc.bridge.signing_key_hex else None
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
    start = sc.ownship.start

    def build(world) -> MavlinkPath:
        bridge = MavlinkBridge(
            sc.bridge.system_id,
            LocalFrame.from_origin(sc.world.origin),
            world,
            link=link,
            signing_key=key,
            command_timeout_s=sc.bridge.command_timeout_s,
            params=params,
            # home on the ground below the start: relative heights are heights above it (h)
            home=(start.x, start.y, 0.0),
            # every command, the planner's or a ground station's, is clamped to these
            alt_limits_m=tuple(sc.world.h),
            speed_limits_mps=aircraft_speed_range(sc.ownship.aircraft),
            bank_limit_rad=math.radians(av.bank_limit_deg),
            accel_limit_mps2=av.accel_mps2,
            xy_limits_m=(tuple(sc.world.x), tuple(sc.world.y)),
            # the link's signing timestamps outlive the run: no replay into the next one
            signing_state=default_state_path(key) if key else None,
            ground_stations=[(g.system_id, g.address) for g in sc.bridge.ground_stations],
            tlog=tlog,
            # a ground station shows the intruders as what they are (a Cessna: LIGHT)
            traffic_emitter=emitter_type(TrafficCategories.from_scenario(sc).intruders),
        )
        encoder = CommandEncoder(sc.bridge.system_id, sc.bridge.system_id, signing_key=key)
        return MavlinkPath(bridge, encoder)

    return build


def member_paths(scenario: Scenario, link: str | None):
    """Fleet member j's command path (docs/fleet.md, "MAVLink per member"): its own bridge,
    MAVLink system ``bridge.system_id + j`` with its home below its own start, its planner's
    commands MAVLink bytes to that system, on its own connection to ``link`` (a link that
    listens, ``udpin``/``udp``/``tcpin``, on port + j). The traffic (ADSB_VEHICLE) is member
    0's bridge's to publish; no tlog of its own."""
    sc = scenario
    starts = sc.member_starts()

    def build(j: int, view) -> MavlinkPath:
        member = sc.model_copy(update={
            "bridge": sc.bridge.model_copy(update={"system_id": sc.bridge.system_id + j}),
            "ownship": sc.ownship.model_copy(update={"start": starts[j]}),
        })  # fmt: skip
        path = mavlink_path(member, member_link(link, j))(view)
        path.show_truth_traffic(False)
        return path

    return build


def member_link(link: str | None, j: int) -> str | None:
    """Member j's connection string: a listening link's port + j (two sockets cannot listen on
    one port), any other link as it is (each member its own socket to the same peer)."""
    if link is None or j == 0:
        return link
    kind, sep, rest = link.partition(":")
    host, _, port = rest.rpartition(":")
    if kind in ("udpin", "udp", "tcpin") and port.isdigit():
        return f"{kind}{sep}{host}:{int(port) + j}"
    return link


def run_spec(scenario: Scenario, service, point=None) -> EpisodeSpec:
    """The episode `uavxai run` flies for ``scenario`` (at its seed): in JSBSim, to the
    scenario's goal (``point``, else ``service``'s point, unless it names one), the mission if
    it has one."""
    point = service.service_point if point is None else point
    return episode_spec(scenario, dynamics="jsbsim", service_point=point, mission=True)


def run_episode(
    scenario: Scenario,
    out: Path,
    *,
    service,
    rerun_file: Path | None = None,
    spawn: bool = False,
    mavlink: str | None = None,
    realtime: float | None = None,
    record: bool | None = None,
    progress=None,
) -> dict:
    """Fly one seeded episode through MAVLink in JSBSim; write trajectory.csv,
    decisions.jsonl and run.rrd into ``out``; return its summary (README "What a run produces")."""
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.comms.channel import Channel
    from uavxai.sim.companion import Companion

    sc = scenario
    placement = fleet_placement(sc, service.users) if sc.fleet.size > 1 else None
    spec = run_spec(sc, service, None if placement is None else placement.positions[0])
    config, checkpoint = PlannerConfig.from_scenario(sc), sc.avoidance.checkpoint
    # On its own core, as on a UAV's companion computer: it searches while the world flies
    # (the intruders, with an instant decision; everyone, with a latency).
    planner = Companion(sc.avoidance.planner, config, checkpoint, scenario=sc)
    channel = Channel.from_scenario(sc, users=service.users)
    url = mavlink if mavlink is not None else sc.bridge.mavlink
    record = sc.log.rerun if record is None else record
    rerun = None
    if record or spawn or rerun_file is not None:
        # --spawn records to the file too: a viewer problem never loses the run's recording
        link = (channel, service.power_w)  # the recorder's metrics/sum_rate_bps
        rerun = _rerun(sc, service, rerun_file or out / "run.rrd", spawn, link)
    steps, observers = run_parts(
        spec, channel, service.power_w, out, placement, member_paths(sc, url), rerun
    )
    if rerun is not None:
        observers.append(rerun)
    if realtime:
        observers.append(Pacing(realtime))
    if progress is not None:
        observers.append(ProgressBar(progress, sc.name, sc.avoidance.max_steps))
    extra = {
        **service.to_summary(),
        "goal_is_service_point": sc.ownship.goal is None,
        "versions": versions(),
    }
    observers.append(SummaryJSON(out / "summary.json", extra))  # last: once the files are closed
    try:
        result = fly(
            spec,
            planner,
            path=mavlink_path(sc, url, out / "link.tlog" if sc.bridge.tlog else None),
            observers=observers,
            engine_steps=steps,
        )
    finally:
        with interrupts_deferred():  # the planner's process is closed in order, not cut off
            planner.close()
    return result.summary


def run_parts(
    spec: EpisodeSpec,
    channel,
    power_w: np.ndarray,
    out: Path,
    placement=None,
    paths=None,
    rerun: Rerun | None = None,
) -> tuple[list[EngineStep], list[Observer]]:
    """What a run adds to its episode: its engine steps, in their order after the picture,
    the operators and the mission (the battery: home at its reserve, the end when empty; then,
    with a mission, the service: users walk, it re-plans and moves the station), and the
    observers of its files in ``out`` (any order: they only observe). A fleet's members each
    write their own ``decisions-j.jsonl`` and their decisions into ``rerun``, the run's
    recording (the caller observes the run with it)."""
    from uavxai.sim.observers import TrajectoryCSV

    sc = spec.scenario
    energy = Energy()
    steps: list[EngineStep] = [energy]
    if placement is not None:  # a fleet (docs/fleet.md): its members, then its service
        from uavxai.sim.fleet import Fleet, FleetService

        watch = [lambda j: DecisionsJSONL(out / decisions_file(j))]
        if rerun is not None:
            watch.append(rerun.member)
        fleet = Fleet(sc, placement.positions, _member_planner(sc), spec.max_steps, paths, watch)
        steps += [fleet, FleetService(sc, channel, placement, fleet, out)]
    elif spec.mission is not None:
        steps.append(Service(sc, channel, power_w, out, replan=_replanner(sc), energy=energy))
    observers: list[Observer] = [
        Throughput(channel, power_w),
        Trust(),
        TrajectoryCSV(out / "trajectory.csv"),
        DecisionsJSONL(out / decisions_file()),
        QuickLook(out / PLOT, channel, power_w, energy, sc.avoidance.d_min_m),
    ]
    return steps, observers


def fleet_placement(sc: Scenario, users: np.ndarray):
    """The fleet's joint placement for the run's users (docs/fleet.md)."""
    from uavxai.sim.fleet import fleet_stations

    return fleet_stations(sc, users)


def _member_planner(sc: Scenario):
    """Fleet member j's own planner, in this process, seeded apart from the others'."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig

    def planner(j: int):
        av = sc.avoidance
        p = make_planner(av.planner, PlannerConfig.from_scenario(sc), checkpoint=av.checkpoint)
        p.reset(int(np.random.SeedSequence([sc.seed, j]).generate_state(1)[0]))
        return p

    return planner


def _replanner(sc: Scenario):
    """Re-plan the service point for users where they are now, with the scenario's planner."""
    from uavxai.service.stage import plan_service

    def replan(users: np.ndarray):
        comms = sc.comms
        users_now = comms.users.model_copy(update={"positions": [tuple(u[:2]) for u in users]})
        moved = sc.model_copy(update={"comms": comms.model_copy(update={"users": users_now})})
        plan = plan_service(moved)
        return plan.service_point, plan.power_w

    return replan


def _rerun(sc: Scenario, service, path: Path, spawn: bool, link: tuple) -> Rerun:
    from uavxai.recording.recorder import RecorderProcess

    recorder = RecorderProcess(
        path,
        spawn=spawn,
        recording_name="uavxai",
        recording_id=f"{sc.name}-seed{sc.seed}",
    )
    setup = {
        "bounds": {"x": sc.world.x, "y": sc.world.y, "h": sc.world.h},
        "users": service.users,
        "service_point": service.service_point,
        "search_path": service.visited,
        "origin": sc.world.origin,
        "link": link,
    }
    return Rerun(recorder, setup)


def versions() -> dict[str, str]:
    import jsbsim
    import torch

    return {"uavxai": __version__, "jsbsim": jsbsim.__version__, "torch": torch.__version__}


def aggregate(episodes: list[dict]) -> dict:
    """Rates and means over several episodes of one run."""
    from uavxai.vocabulary import Outcome

    n = len(episodes)
    outcomes = [e["outcome"] for e in episodes]
    seps = [e["min_separation_m"] for e in episodes if e["min_separation_m"] is not None]
    rates = {f"{o.value}_rate": outcomes.count(o.value) / n for o in Outcome}
    return {
        "episodes_run": n,
        **rates,
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
    """`uavxai run`: one episode writes into ``out``; several write ``out/episode-NNN/`` each
    and a summary.json with the list and the aggregates."""
    from uavxai.progress import progress_bar
    from uavxai.service.stage import plan_service

    results = []
    with progress_bar(console) as progress:
        for i in range(episodes):
            sc = scenario.with_seed(scenario.seed + i)
            ep_out = out if episodes == 1 else out / f"episode-{i:03d}"
            ep_out.mkdir(parents=True, exist_ok=True)
            rrd = rerun_file
            if rerun_file and episodes > 1:
                rrd = rerun_file.with_name(f"{rerun_file.stem}-{i:03d}{rerun_file.suffix}")
            summary = run_episode(
                sc,
                ep_out,
                service=plan_service(sc),
                rerun_file=rrd,
                spawn=spawn,
                mavlink=mavlink,
                realtime=realtime,
                progress=progress,
            )
            results.append(summary)  # its summary.json is written: see SummaryJSON
            if summary["outcome"] == "interrupted":
                break
    if episodes == 1:
        final = results[0]
    else:
        final = {
            "scenario": scenario.name,
            "seed": scenario.seed,
            "episodes": results,
            **aggregate(results),
        }
        interrupted = any(e["outcome"] == "interrupted" for e in results)
        with interrupts_deferred(deliver=not interrupted):
            write_output(out / "summary.json", json.dumps(final, indent=2) + "\n")
    report(final, out, rerun_file, spawn)
    return final


def report(summary: dict, out: Path, rerun_file: Path | None, spawn: bool) -> None:
    eps = summary.get("episodes", [summary])
    for e in eps:
        sep = e["min_separation_m"]
        where = (
            "at the service point"
            if e.get("goal_is_service_point", True)
            else "at the service point (not flown: the scenario names its own goal)"
        )
        console.print(
            f"[bold]{e['scenario']}[/] seed {e['seed']}: [bold]{e['outcome']}[/] after "
            f"{e['steps']} decisions, {e['flight_time_s']:.0f} s flown; min separation "
            f"{'-' if sep is None else f'{sep:.0f} m'}; sum rate {e['sum_rate_bps'] / 1e6:.2f} "
            f"Mbit/s {where}; decision p50 {e['decision_ms']['p50'] or 0:.1f} ms; "
            f"{e['sim_realtime_factor'] or 0:.1f}x real time"
        )
        console.print(_safety_line(e))
        if e.get("fleet"):
            console.print(_fleet_line(e["fleet"]))
            for d in e.get("fleet_departures", []):
                console.print(_departure_line(d))
        elif e.get("mission", {}).get("delivered_bits") is not None:
            console.print(_mission_line(e["mission"]))
    n = len(eps[0].get("fleet") or [])  # a fleet's other members write their own (docs/fleet.md)
    more = {0: "", 1: "", 2: ", decisions-1.jsonl"}.get(n, f", decisions-1 .. {n - 1}.jsonl")
    console.print(
        f"outputs in {out}/ (summary.json, trajectory.csv, decisions.jsonl{more}, {PLOT})"
    )
    rrd = rerun_file or out / "run.rrd"  # written with or without --spawn
    if len(eps) > 1 and rerun_file is None:
        rrd = out / "episode-000" / "run.rrd"
    if rrd.exists():
        viewer = Path(sys.executable).parent / "rerun"  # installed with rerun-sdk
        viewer_cmd = str(viewer) if viewer.exists() else "rerun"
        console.print(f"recording: {rrd}  — open it with:  {viewer_cmd} {rrd}")
    first = out if len(eps) == 1 else out / "episode-000"
    console.print(f"explain a decision:  {invocation()} explain {first} --decision 0")


def _safety_line(e: dict) -> str:
    """Near mid-air collision or not, how far the explanations' predictions were from the
    flight (summary.json's ``trust``), and why JSBSim stopped or lost an intruder, if it did."""
    err = (e.get("trust") or {}).get("separation_error_m") or {}
    trust = (
        "no predictions to check"
        if err.get("p95") is None
        else f"mean {err['mean']:.0f} m, p95 {err['p95']:.0f} m, max {err['max']:.0f} m"
    )
    line = (
        f"  safety: NMAC {'yes' if e.get('nmac') else 'no'}; predicted against flown "
        f"separation (trust): {trust}"
    )
    if e.get("failure"):
        line += f"; dynamics failure: {e['failure']}"
    if e.get("intruders_lost"):
        line += f"; {len(e['intruders_lost'])} intruder(s) lost in flight and replaced"
    return line


def _fleet_line(fleet: list[dict]) -> str:
    """Each UAV of a fleet: outcome, closest approach, delivery, energy."""

    def one(u: dict) -> str:
        sep, wh = u["min_separation_m"], u["energy_wh"]
        return (
            f"{u['id']} {u['outcome']}, min sep {'-' if sep is None else f'{sep:.0f} m'}, "
            f"{u.get('delivered_bits', 0.0) / 1e6:.0f} Mbit to {len(u.get('users_served', []))} "
            f"users, {'-' if wh is None else f'{wh:.1f} Wh'}"
        )

    return "  fleet: " + "; ".join(one(u) for u in fleet)


def _departure_line(d: dict) -> str:
    """A fleet member that left early: whom its users went to, their QoS share before and
    after (docs/fleet.md, "A member leaving early")."""

    def pct(share: float | None) -> str:
        return "-" if share is None else f"{100 * share:.0f} %"

    to = sorted({d["association_after"][k] for k in d["users"]} - {-1})
    back = d["recovered_after_s"]
    return (
        f"  UAV {d['uav']} left at {d['t']:.0f} s ({d['why']}): its {len(d['users'])} users "
        f"re-covered by UAV {', '.join(map(str, to)) or '-'}; their QoS share "
        f"{pct(d['qos_share_before'])} before, {pct(d['qos_share_after'])} after (the crowd's "
        f"{pct(d['crowd_qos_share_before'])}, {pct(d['crowd_qos_share_after'])}); all at QoS "
        f"again {'never' if back is None else f'{back:.1f} s after'}"
    )


def _mission_line(m: dict) -> str:
    """The mission's service, energy and battery in one line."""
    energy, soc = m.get("energy_wh"), m.get("battery_soc_end")
    qos = 100 * m["qos_user_seconds_share"]
    return (
        f"  mission: {m['on_station_s']:.0f} s on station ({m['avoiding_s']:.0f} s avoiding), "
        f"{len(m['service_points'])} service point(s); delivered "
        f"{m['delivered_bits'] / 1e6:.0f} Mbit, QoS met {qos:.0f} % of user-seconds, Jain "
        f"{m['jain_fairness']:.2f}, lost to avoidance {m['avoidance_lost_bits'] / 1e6:.1f} "
        f"Mbit; energy {'-' if energy is None else f'{energy:.1f} Wh'}, battery at the end "
        f"{'-' if soc is None else f'{100 * soc:.0f} %'}"
    )
