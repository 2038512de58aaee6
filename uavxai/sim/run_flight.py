"""The episode `uavxai run` flies: scenario -> service point -> JSBSim world -> avoidance
planner -> MAVLink bytes -> bridge -> JSBSim autopilot -> recordings, and the files it writes
(:func:`run_episode`). The planner never touches the aircraft: its decision is encoded as MAVLink
2 messages, decoded by the bridge, and only the bridge writes the autopilot's setpoints — the
same path an external peer on ``--mavlink`` uses.

Apart from the command (:mod:`uavxai.sim.run`: episodes, console report) so that a fleet
campaign (`uavxai evaluate` of a fleet, :mod:`uavxai.campaign.fleet`) flies each episode by
this very code, not a second fleet flight, without depending on the run command.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from uavxai import __version__
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
    encounters: list[Observer] = []  # a fleet's, member with member and with traffic
    if placement is not None:  # a fleet (docs/fleet.md): its members, then its service
        from uavxai.sim.fleet import Fleet, FleetService
        from uavxai.sim.fleet_record import FleetEncounters

        watch = [lambda j: DecisionsJSONL(out / decisions_file(j))]
        if rerun is not None:
            watch.append(rerun.member)
        fleet = Fleet(sc, placement.positions, _member_planner(sc), spec.max_steps, paths, watch)
        steps += [fleet, FleetService(sc, channel, placement, fleet, out)]
        encounters = [FleetEncounters.from_scenario(sc)]
    elif spec.mission is not None:
        steps.append(Service(sc, channel, power_w, out, replan=_replanner(sc), energy=energy))
    observers: list[Observer] = [
        Throughput(channel, power_w),
        Trust(),
        TrajectoryCSV(out / "trajectory.csv"),
        DecisionsJSONL(out / decisions_file()),
        QuickLook(out / PLOT, channel, power_w, energy, sc.avoidance.d_min_m),
        *encounters,
    ]
    return steps, observers


def fleet_placement(sc: Scenario, users: np.ndarray):
    """The fleet's joint placement for the run's users (docs/fleet.md)."""
    from uavxai.sim.fleet import fleet_stations

    return fleet_stations(sc, users)


def _member_planner(sc: Scenario):
    """Fleet member j's own planner, in this process, seeded apart from the others'. The
    compiled search is loaded here, at set-up (:func:`uavxai.sim.companion.warm_up`), not at
    the first member's first decision in flight."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.companion import warm_up

    av = sc.avoidance
    warm_up(av.planner, PlannerConfig.from_scenario(sc), av.checkpoint)

    def planner(j: int):
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
