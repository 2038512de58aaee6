"""A fleet campaign (`uavxai evaluate` of a scenario with ``fleet.size`` > 1; docs/fleet.md,
"Fleet campaigns"): its episode and its rows.

Episode ``i`` of method M with N intruders is the fleet mission `uavxai run` flies at seed
``scenario.seed + i``, flown by `uavxai run`'s own code (:func:`uavxai.sim.run_flight.run_episode`:
JSBSim, each member's MAVLink bridge, the companion planner; no recording), on the scenario
with ``avoidance.planner: M`` (every member flies it) and ``intruders.count: N``; so with the
scenario's own planner and count the row is the `uavxai run --seed` of that seed, and the run's
files are kept in the episode's folder (:func:`episode_folder`). Its ``fleet_episodes.csv`` row
is read from that run's summary (``summary.fleet``, ``summary.mission``,
``summary.fleet_encounters``, ``summary.fleet_departures``); ``fleet_results.csv`` has one row
per method and intruder count, its rates with 95 % Wilson intervals.
"""

from __future__ import annotations

import math
import tempfile
import time
from collections.abc import Iterable
from pathlib import Path

import numpy as np

from uavxai.campaign.files import (
    FLEET_EPISODE_COLUMNS,
    FLEET_EPISODES,
    FLEET_RESULT_COLUMNS,
    FLEET_RESULTS,
    as_written,
    write_csv,
)
from uavxai.errors import UserError
from uavxai.outputs import cell_number
from uavxai.scenario import Scenario

RUNS = "fleet-runs"  # the campaign folder's subfolder of the episodes' run files


def fleet_scenario(scenario: Scenario, method: str, n_intruders: int) -> Scenario:
    """``scenario`` with every member flying ``method`` and ``n_intruders`` random intruders,
    checked as a scenario file would be (a fleet refuses what it cannot fly, by name).

    The copy has no external link (docs/fleet.md, "Fleet campaigns"): no ``bridge.mavlink``
    (no socket: two workers would listen on one port, an outside peer could command the
    flight, and a row would no longer be its scenario and seed's), no ``link.tlog``, no
    signing key (no signing state file shared by episodes) and no ground stations; the
    in-process bridges keep their system ids and command time-out, as a one-ownship
    campaign, which never opens a link."""
    from pydantic import ValidationError

    data = scenario.model_dump()
    data["avoidance"]["planner"] = method
    data["intruders"]["count"] = int(n_intruders)
    data["bridge"].update(mavlink=None, tlog=False, signing_key_hex=None, ground_stations=[])
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        first = exc.errors()[0]
        field = ".".join(str(part) for part in first["loc"]) or "the scenario"
        raise UserError(
            f"--methods {method} --intruders {n_intruders}: scenario '{scenario.name}' cannot "
            f"fly it ({field}: {first['msg']})."
        ) from None


def episode_folder(out: Path, method: str, n_intruders: int, episode: int) -> Path:
    """Where a fleet campaign keeps episode ``episode``'s run files (summary.json,
    trajectory.csv, service.csv, decisions*.jsonl, ...: what `uavxai run` writes)."""
    return out / RUNS / f"{method}-x{n_intruders}-episode-{episode:04d}"


def run_fleet_episode(
    scenario: Scenario, method: str, n_intruders: int, seed: int, folder: Path | None = None
) -> dict:
    """Fly one fleet campaign episode (the fleet mission at ``seed``, as `uavxai run`) and
    return its ``fleet_episodes.csv`` row (without ``episode``); its run's files go into
    ``folder`` (None: a temporary folder, removed)."""
    if folder is None:
        with tempfile.TemporaryDirectory(prefix="uavxai-fleet-") as tmp:
            return run_fleet_episode(scenario, method, n_intruders, seed, Path(tmp))
    from uavxai.service.stage import plan_service
    from uavxai.sim.run_flight import run_episode

    sc = fleet_scenario(scenario, method, n_intruders).with_seed(seed)
    folder.mkdir(parents=True, exist_ok=True)
    wall0 = time.perf_counter()
    summary = run_episode(sc, folder, service=plan_service(sc), record=False)
    wall = time.perf_counter() - wall0
    if summary["outcome"] == "interrupted":
        # a signal to this process: the campaign stops here (its caller keeps the finished
        # episodes), and a flight cut short is no episode of its results
        raise KeyboardInterrupt("episode interrupted")
    return fleet_row(summary, method, n_intruders, wall)


def fleet_row(summary: dict, method: str, n_intruders: int, wall_s: float) -> dict:
    """A fleet run's summary as its ``fleet_episodes.csv`` row (docs/fleet.md)."""
    fleet, mission = summary["fleet"], summary["mission"]
    meet = summary["fleet_encounters"]
    left = summary.get("fleet_departures") or []
    first = left[0] if left else {}

    def each(key: str, fmt: str) -> str:
        return " ".join("-" if u.get(key) is None else format(u[key], fmt) for u in fleet)

    def number(v) -> float | None:  # None: not defined (an empty cell; rows compare equal)
        return None if v is None else float(v)

    def metres(v) -> float:
        return math.inf if v is None else round(float(v), 3)

    energy = [number(u.get("energy_wh")) for u in fleet]
    total_wh = None if None in energy else float(sum(energy))
    return {
        "method": method,
        "intruders": int(n_intruders),
        "seed": int(summary["seed"]),
        "outcome": summary["outcome"],
        "completed": int(all(u["outcome"] == "completed" for u in fleet)),
        "member_outcomes": " ".join(u["outcome"] for u in fleet),
        "flight_time_s": round(float(summary["flight_time_s"]), 3),
        # whole bits: the file keeps the run's number, not six digits of it
        "delivered_bits": round(float(mission["delivered_bits"])),
        "member_delivered_bits": each("delivered_bits", ".0f"),
        "qos_share": number(mission.get("qos_user_seconds_share")),
        "jain_fairness": number(mission.get("jain_fairness")),
        "energy_wh": total_wh,
        "member_energy_wh": each("energy_wh", ".3f"),
        "member_min_separation_m": each("min_separation_m", ".1f"),
        "member_collisions": len(meet["member_collisions"]),
        "intruder_collisions": len(meet["intruder_collisions"]),
        "member_nmacs": len(meet["member_nmacs"]),
        "intruder_nmacs": len(meet["intruder_nmacs"]),
        "closest_members_m": metres(meet["closest_members_m"]),
        "closest_intruder_m": metres(meet["closest_intruder_m"]),
        "departures": len(left),
        "leave_uav": first.get("uav", ""),
        "leave_t_s": number(first.get("t")),
        **{f"leave_{k}": number(first.get(k)) for k in (
            "qos_share_before", "qos_share_after", "crowd_qos_share_before",
            "crowd_qos_share_after", "recovered_after_s")},  # fmt: skip
        "decision_ms_p50": number((summary.get("decision_ms") or {}).get("p50")),
        "wall_s": round(wall_s, 1),
    }


def is_fleet_rows(rows: Iterable[dict]) -> bool:
    """Rows of a fleet campaign (``fleet_episodes.csv``'s), not one ownship's."""
    rows = list(rows)
    return bool(rows) and all("member_outcomes" in r for r in rows)


def write_fleet_campaign(rows: Iterable[dict], out: Path) -> tuple[list[dict], list[dict]]:
    """A fleet campaign's ``fleet_episodes.csv`` and ``fleet_results.csv`` in ``out`` from its
    episodes' rows (`uavxai evaluate`'s, or the sources' pooled by `uavxai merge`: one code
    path). The results are computed from the rows as the file holds them (numbers to six
    digits), so that a campaign pooled from its files equals the one flown whole. Returns
    (the rows as written, the results)."""
    rows = as_written(rows, FLEET_EPISODE_COLUMNS)
    results = summarise_fleet(rows)
    write_csv(out / FLEET_EPISODES, FLEET_EPISODE_COLUMNS, rows)
    write_csv(out / FLEET_RESULTS, FLEET_RESULT_COLUMNS, results)
    return rows, results


def summarise_fleet(rows: Iterable[dict]) -> list[dict]:
    """One ``fleet_results.csv`` row per (method, intruders), in first-seen order: rates with
    their 95 % Wilson interval, the event counts summed, the worst case beside each mean."""
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["method"], int(r["intruders"])), []).append(r)
    return [_fleet_result(m, n, rs) for (m, n), rs in groups.items()]


def _fleet_result(method: str, n: int, rs: list[dict]) -> dict:
    from uavxai.metrics import rate

    def col(key: str) -> np.ndarray:
        return np.array([cell_number(r.get(key)) for r in rs], dtype=float)

    def finite(key: str) -> np.ndarray:
        v = col(key)
        return v[np.isfinite(v)]

    def mean(key: str) -> float:
        v = finite(key)
        return float(v.mean()) if v.size else math.nan

    def worst(key: str, pick) -> float:
        v = col(key)
        v = v[~np.isnan(v)]
        return float(pick(v)) if v.size else math.nan

    def whole(v: float) -> float | int:  # bits: whole numbers in the file, not six digits
        return round(v) if math.isfinite(v) else v

    outcomes = [r["outcome"] for r in rs]
    k = len(rs)
    row: dict = {"method": method, "intruders": n, "episodes": k}
    events = {
        "completed_rate": col("completed") > 0.5,
        "collision_rate": np.array([o == "collision" for o in outcomes]),
        "member_nmac_rate": col("member_nmacs") > 0,
        "intruder_nmac_rate": col("intruder_nmacs") > 0,
    }
    for name, happened in events.items():
        r = rate(happened)
        row[name], row[f"{name}_lo"], row[f"{name}_hi"] = r.rate, r.lo, r.hi
    for o in ("timeout", "out_of_bounds", "fdm_failure"):
        row[f"{o}_rate"] = outcomes.count(o) / k
    for key in ("member_collisions", "intruder_collisions", "member_nmacs", "intruder_nmacs"):
        row[key] = int(col(key).sum())
    row.update({
        "min_closest_members_m": worst("closest_members_m", np.min),
        "min_closest_intruder_m": worst("closest_intruder_m", np.min),
        "mean_delivered_bits": whole(mean("delivered_bits")),
        "min_delivered_bits": whole(worst("delivered_bits", np.min)),
        "mean_qos_share": mean("qos_share"),
        "min_qos_share": worst("qos_share", np.min),
        "mean_jain_fairness": mean("jain_fairness"),
        "min_jain_fairness": worst("jain_fairness", np.min),
        "mean_energy_wh": mean("energy_wh"),
        "max_energy_wh": worst("energy_wh", np.max),
        "mean_leave_qos_share_before": mean("leave_qos_share_before"),
        "mean_leave_qos_share_after": mean("leave_qos_share_after"),
        "min_leave_qos_share_after": worst("leave_qos_share_after", np.min),
        # a departure after which its users never came back to their share before it
        "leave_never_recovered": sum(
            1 for r in rs
            if str(r.get("leave_uav", "")) != "" and math.isnan(cell_number(r.get(
                "leave_recovered_after_s")))),  # fmt: skip
        "max_leave_recovered_after_s": worst("leave_recovered_after_s", np.max),
        "mean_wall_s": mean("wall_s"),
    })  # fmt: skip
    return row


def fleet_table(results: Iterable[dict]):
    """A fleet campaign's results for the terminal."""
    from rich.table import Table

    def ci(r: dict, key: str) -> str:
        return f"{r[key]:.3f} [{r[f'{key}_lo']:.3f}, {r[f'{key}_hi']:.3f}]"

    t = Table("method", "intruders", "episodes", "completed (95 % CI)", "collision (95 % CI)",
              "member NMACs", "intruder NMACs", "closest members m", "Mbit mean (min)",
              "QoS share mean (min)", "Jain mean (min)", "Wh mean (max)",
              title="fleet campaign")  # fmt: skip
    for r in results:
        t.add_row(
            r["method"], str(r["intruders"]), str(r["episodes"]), ci(r, "completed_rate"),
            ci(r, "collision_rate"), str(r["member_nmacs"]), str(r["intruder_nmacs"]),
            f"{r['min_closest_members_m']:.1f}",
            f"{r['mean_delivered_bits'] / 1e6:,.0f} ({r['min_delivered_bits'] / 1e6:,.0f})",
            f"{r['mean_qos_share']:.3f} ({r['min_qos_share']:.3f})",
            f"{r['mean_jain_fairness']:.3f} ({r['min_jain_fairness']:.3f})",
            f"{r['mean_energy_wh']:.1f} ({r['max_energy_wh']:.1f})",
        )  # fmt: skip
    return t
