"""`uavxai evaluate`: a campaign with a progress bar, each finished episode journaled (resumable),
its files and figures written whole (those of an interrupted one too), and its tables printed.
"""

from __future__ import annotations

import math
import sys
import time
from collections.abc import Sequence
from pathlib import Path

from uavxai.campaign.episode import planner_for
from uavxai.campaign.files import FLEET_EPISODES, FLEET_RESULTS, columns_of, write_csv
from uavxai.campaign.fleet import RUNS, fleet_table, is_fleet_rows, write_fleet_campaign
from uavxai.campaign.plots import plot_campaign, plot_fleet
from uavxai.campaign.runner import check_campaign, run_campaign, versions
from uavxai.campaign.statistics import summarise
from uavxai.outputs import cell_number
from uavxai.processes import interrupts_deferred
from uavxai.scenario import Scenario


def _campaign_goal(scenario: Scenario, goal: Sequence[float] | None, console) -> tuple:
    """Where every episode flies, said on ``console``: ``goal``, or None: the scenario's
    (``ownship.goal``, else its service point). `uavxai evaluate --seed N` passes the goal of
    the scenario file's own seed, so that a campaign extended with another seed flies to the
    same goal and merges with the first."""
    from uavxai.sim.spec import episode_goal

    if scenario.fleet.size > 1:
        console.print(f"fleet of {scenario.fleet.size}: each member's station and users planned "
                      "per episode (the fleet's joint placement of its seed's users)")  # fmt: skip
        return ()
    goal = tuple(float(g) for g in (episode_goal(scenario) if goal is None else goal))
    where = "ownship.goal" if scenario.ownship.goal is not None else "the service point"
    console.print(f"goal ({where}): ({goal[0]:.0f}, {goal[1]:.0f}, {goal[2]:.0f}) m")
    return goal


def evaluate_command(
    scenario: Scenario,
    methods: list[str],
    intruders: list[int],
    episodes: int,
    dynamics: str,
    workers: int,
    ray_address: str | None,
    out: Path,
    goal: Sequence[float] | None = None,
    resume: bool = False,
) -> dict:
    """The `uavxai evaluate` command: the campaign with a progress bar, each finished episode
    journaled (:mod:`uavxai.journal`), ``results.csv``, ``episodes.csv`` and the plots in
    ``out`` (a fleet's: ``fleet_results.csv``, ``fleet_episodes.csv``, its plots and each
    episode's run files under ``fleet-runs/``; docs/fleet.md, "Fleet campaigns"); a short report
    back. ``goal``: see :func:`_campaign_goal`; ``resume``: fly only
    what an interrupted run of the same campaign did not journal in ``out``."""
    import torch
    from rich.console import Console

    from uavxai.journal import Journal, campaign_header, read_journal
    from uavxai.progress import progress_bar

    torch.set_num_threads(1)
    check_campaign(scenario, methods, intruders, episodes, dynamics, workers)
    # Load every planner once here: a missing checkpoint fails now, not in a worker.
    for m in methods:
        planner_for(scenario, m)
    total = len(methods) * len(intruders) * episodes
    # Piped output gets a wide table rather than column names cut to fit 80 characters.
    console = Console(stderr=True, width=None if sys.stderr.isatty() else 200)
    wall0 = time.perf_counter()
    goal = _campaign_goal(scenario, goal, console)
    header = campaign_header(scenario, methods, intruders, episodes, dynamics, goal, versions())
    before = read_journal(out, header) if resume else {}
    if resume:
        console.print(f"resuming: {len(before)} of {total} episodes already flown in {out}")
    journal = Journal(out, header)
    with progress_bar(console) as progress:
        bar = progress.add_task(f"{scenario.name} ({dynamics})", total=total)
        progress.update(bar, advance=len(before))

        finished: list[dict] = list(before.values())

        def done(row: dict) -> None:
            journal.append(row)
            finished.append(row)
            progress.update(
                bar, advance=1, description=f"{row['method']} x{row['intruders']}: {row['outcome']}"
            )

        try:
            rows = run_campaign(
                scenario,
                methods,
                intruders,
                episodes,
                dynamics=dynamics,
                workers=workers,
                ray_address=ray_address,
                on_done=done,
                goal=goal,
                finished=before,
                out=out,
            )
        except KeyboardInterrupt:
            _keep_finished(finished, out, console)
            raise
        finally:
            journal.close()
    results, plots = _save(rows, out, f"{scenario.name}, {dynamics}, {episodes} episodes")
    wall = time.perf_counter() - wall0
    _report(rows, results, plots, out, console)
    return {"episodes": len(rows), "wall_s": wall, "results": results}


def _report(rows: list[dict], results: list[dict], plots: list[Path], out: Path, console) -> None:
    """A finished campaign's tables and files, on ``console``."""
    if is_fleet_rows(rows):
        console.print(fleet_table(results))
        console.print(f"wrote {out / FLEET_RESULTS}, {out / FLEET_EPISODES}, each episode's "
                      f"run files in {out / RUNS}/ and {len(plots)} plots: "
                      f"{', '.join(str(p) for p in plots)}")  # fmt: skip
        return
    console.print(results_table(results))
    if any(math.isfinite(cell_number(r.get("nmac_prob"))) for r in results):
        console.print(daa_table(results))
    console.print(f"wrote {out / 'results.csv'}, {out / 'episodes.csv'} and {len(plots)} plots")


def _save(rows: list[dict], out: Path, title: str) -> tuple[list[dict], list[Path]]:
    """A finished campaign's ``episodes.csv``, ``results.csv`` and plots; a signal that comes
    meanwhile waits for them to be whole. Its results and the plots' paths (a fleet
    campaign's: fleet_episodes.csv, fleet_results.csv and its plots)."""
    with interrupts_deferred():
        if is_fleet_rows(rows):
            out.mkdir(parents=True, exist_ok=True)
            rows, results = write_fleet_campaign(rows, out)
            return results, plot_fleet(results, rows, out, title)
        results = _write_rows(rows, out)
        return results, plot_campaign(results, out, title)


def _write_rows(rows: list[dict], out: Path) -> list[dict]:
    """A campaign's two files from its episodes' rows; its results."""
    out.mkdir(parents=True, exist_ok=True)
    if is_fleet_rows(rows):
        return write_fleet_campaign(rows, out)[1]
    results = summarise(rows)
    episode_columns, result_columns = columns_of(rows)
    write_csv(out / "episodes.csv", episode_columns, rows)
    write_csv(out / "results.csv", result_columns, results)
    return results


def _keep_finished(rows: list[dict], out: Path, console) -> None:
    """An interrupted campaign still writes the episodes that finished (and their results)."""
    if not rows:
        return
    order = {(m, n, e): k for k, (m, n, e) in enumerate(sorted(
        (r["method"], r["intruders"], r["episode"]) for r in rows))}  # fmt: skip
    rows = sorted(rows, key=lambda r: order[(r["method"], r["intruders"], r["episode"])])
    # Already ending for a signal: another one (a second Ctrl-C, a supervisor's repeated
    # SIGTERM) must not cut the files short, and changes nothing after them.
    with interrupts_deferred(deliver=False):
        _write_rows(rows, out)
        files = ((FLEET_EPISODES, FLEET_RESULTS) if is_fleet_rows(rows)
                 else ("episodes.csv", "results.csv"))  # fmt: skip
        console.print(
            f"interrupted: kept the {len(rows)} finished episodes in {out / files[0]} "
            f"and {out / files[1]}; the same command with --resume flies the others"
        )


def results_table(results: Sequence[dict]):
    from rich.table import Table

    def ci(r: dict, key: str) -> str:
        v, lo, hi = r[key], r[f"{key}_lo"], r[f"{key}_hi"]
        return "-" if math.isnan(v) else f"{v:.3f} [{lo:.3f}, {hi:.3f}]"

    t = Table("method", "intruders", "episodes", "goal", "collision (95 % CI)", "NMAC (95 % CI)",
              "risk ratio (95 % CI)", "steps", "path excess p50", "reversals/min",
              "ms p50")  # fmt: skip
    for r in results:
        t.add_row(
            r["method"],
            str(r["intruders"]),
            str(r["episodes"]),
            f"{r['goal_rate']:.3f}",
            ci(r, "collision_rate"),
            ci(r, "nmac_rate"),
            ci(r, "risk_ratio"),
            f"{r['mean_steps']:.1f}",
            f"{cell_number(r.get('median_path_excess')):.1%}",
            f"{cell_number(r.get('mean_reversals_per_min')):.1f}",
            f"{r['decision_ms_p50']:.2f}",
        )
    return t


def daa_table(results: Sequence[dict]):
    """The weighted detect-and-avoid columns of a campaign, one row per method and intruder
    count (an encounter campaign's: one intruder each)."""
    from rich.table import Table

    def ci(r: dict, key: str) -> str:
        v, lo, hi = (cell_number(r.get(k)) for k in (key, f"{key}_lo", f"{key}_hi"))
        return "-" if math.isnan(v) else f"{v:.3g} [{lo:.3g}, {hi:.3g}]"

    t = Table("method", "intruders", "episodes", "P(NMAC)", "NMAC risk ratio", "induced", "P(LoWC)",
              "LoWC ratio", "alert rate", "unnecessary manoeuvre", "reversals", "path excess",
              "CI check", title="detect and avoid (weighted, 95 % bootstrap)")  # fmt: skip
    for r in results:
        t.add_row(r["method"], str(r["intruders"]), str(r["episodes"]), ci(r, "nmac_prob"),
                  ci(r, "nmac_risk_ratio"), ci(r, "induced_risk_ratio"), ci(r, "lowc_prob"),
                  ci(r, "lowc_ratio"),
                  ci(r, "alert_rate"), ci(r, "unnecessary_manoeuvre_rate"),
                  f"{cell_number(r.get('mean_reversals')):.2f}",
                  f"{cell_number(r.get('mean_path_excess')):.4f}", str(r.get("ci_check", "")))
    return t
