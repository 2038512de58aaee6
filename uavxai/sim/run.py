"""`uavxai run`: the whole co-simulation, one seeded episode at a time, and its console report.

The episode itself (scenario -> service point -> JSBSim world -> avoidance planner -> MAVLink
bytes -> bridge -> JSBSim autopilot -> recordings) is :mod:`uavxai.sim.run_flight`'s
:func:`run_episode`, which a fleet campaign flies too; its parts are re-exported here.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
from rich.console import Console

from uavxai.outputs import write_output
from uavxai.paths import invocation
from uavxai.processes import interrupts_deferred
from uavxai.scenario import Scenario
from uavxai.sim.quicklook import PLOT
from uavxai.sim.run_flight import (
    fleet_placement,
    mavlink_path,
    member_link,
    member_paths,
    run_episode,
    run_parts,
    run_spec,
    versions,
)

__all__ = [
    "aggregate",
    "fleet_placement",
    "mavlink_path",
    "member_link",
    "member_paths",
    "report",
    "run_command",
    "run_episode",
    "run_parts",
    "run_spec",
    "versions",
]

console = Console(stderr=True, soft_wrap=True)


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
