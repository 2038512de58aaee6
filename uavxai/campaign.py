"""`uavxai evaluate`: Monte Carlo campaigns of the avoidance stage (the paper's figures).

A campaign flies every method against every intruder count for ``episodes`` seeded episodes.
Episode ``i`` uses seed ``scenario.seed + i`` for every method and every count, so methods
meet the same encounters (the same start, goal and intruders) and any row of
``episodes.csv`` can be flown again alone::

    python -c "from uavxai.campaign import rerun_row; print(rerun_row('scenarios/demo.yaml', \
'mcts', 20, 17))"

(scenario file, method, intruders, seed; ``dynamics='jsbsim'`` for a JSBSim row).

Episodes run in this process (``workers=1``), in local worker processes (``workers>1``; the
``forkserver`` context, one torch thread each) or as Ray tasks (``ray_address``: ``local``
starts a private Ray instance on this machine, ``auto`` joins the cluster this machine belongs
to, ``ray://host:port`` a remote one whose nodes have uavxai installed). Wherever an episode
runs, its numbers are the same: only the ``decision_ms`` timings differ.

``dynamics='kinematic'`` flies the episode on the encounter model
(:func:`uavxai.avoidance.episode.run_episode`); ``'jsbsim'`` flies the same start, goal and
intruders in the JSBSim world (:func:`run_jsbsim_episode`: no MAVLink, no recording; the
planner's commands go straight to the ownship's autopilot).
"""

from __future__ import annotations

import csv
import math
import multiprocessing
import os
import time
from collections.abc import Callable, Iterable, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

import numpy as np

from uavxai.errors import UserError
from uavxai.scenario import Scenario

METHODS = ("mcts", "mcts_fast", "exhaustive", "dqn", "safe_dqn", "none")
DYNAMICS = ("kinematic", "jsbsim")
OUTCOMES = ("goal", "collision", "timeout", "out_of_bounds")
RESULT_COLUMNS = (
    "method",
    "intruders",
    "episodes",
    "goal_rate",
    "collision_rate",
    "timeout_rate",
    "mean_steps",
    "mean_min_separation_m",
    "decision_ms_p50",
    "out_of_bounds_rate",
)
EPISODE_COLUMNS = (
    "method",
    "intruders",
    "episode",
    "seed",
    "outcome",
    "steps",
    "min_separation_m",
    "flight_time_s",
    "decision_ms_p50",
)
# The columns whose values depend on the machine, not on the seed.
TIMING_COLUMNS = ("decision_ms_p50",)
JSBSIM_SAMPLE_HZ = 10.0  # collision checks between samples at this rate, by closest approach

# One planner per (method, scenario) per process: loading a network or building a model once.
_PLANNERS: dict[tuple[str, str], object] = {}


# ------------------------------------------------------------------------------ one episode
def _planner(scenario: Scenario, method: str):
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig

    key = (method, scenario.model_dump_json())
    planner = _PLANNERS.get(key)
    if planner is None:
        config = PlannerConfig.from_scenario(scenario)
        planner = make_planner(method, config, checkpoint=scenario.avoidance.checkpoint)
        _PLANNERS[key] = planner
    return planner


def run_campaign_episode(
    scenario: Scenario,
    method: str,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
) -> dict:
    """Fly one campaign episode and return its ``episodes.csv`` row (without ``episode``),
    plus ``decision_ms`` (every decision's planner time, for the pooled median)."""
    if method not in METHODS:
        raise UserError(f"method '{method}' is not one of {', '.join(METHODS)}.")
    if dynamics not in DYNAMICS:
        raise UserError(f"dynamics '{dynamics}' is not one of {', '.join(DYNAMICS)}.")
    planner = _planner(scenario, method)
    planner.reset(seed)
    if dynamics == "kinematic":
        from uavxai.avoidance.episode import run_episode

        r = run_episode(planner, scenario, seed, n_intruders)
        outcome, steps = r.outcome, r.steps
        min_sep, flight_time, ms = r.min_separation_m, r.flight_time_s, list(r.decision_ms)
    else:
        outcome, steps, min_sep, flight_time, ms = run_jsbsim_episode(
            planner, scenario, seed, n_intruders
        )
    return {
        "method": method,
        "intruders": int(n_intruders),
        "seed": int(seed),
        "outcome": outcome,
        "steps": int(steps),
        "min_separation_m": round(float(min_sep), 3) if math.isfinite(min_sep) else math.inf,
        "flight_time_s": round(float(flight_time), 3),
        "decision_ms_p50": round(float(np.median(ms)), 4) if ms else math.nan,
        "decision_ms": ms,
    }


def rerun_row(
    scenario_path: str | Path,
    method: str,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
) -> dict:
    """Fly one row of an ``episodes.csv`` again: its scenario file, method, intruders, seed."""
    from uavxai.scenario import load_scenario

    row = run_campaign_episode(load_scenario(scenario_path), method, n_intruders, seed, dynamics)
    row.pop("decision_ms")
    return row


def run_jsbsim_episode(
    planner, scenario: Scenario, seed: int, n_intruders: int
) -> tuple[str, int, float, float, list[float]]:
    """The kinematic episode's start, goal and intruders, flown in the JSBSim world.

    The planner decides every ``decision_period_s`` from the world's state; its bank and
    acceleration commands go straight to the ownship's autopilot. Collisions are checked by
    the closest approach between 10 Hz samples, both aircraft moving linearly in between, so a
    pass-through between samples counts. Returns (outcome, steps, min separation m, flight
    time s, planner ms per decision).
    """
    from uavxai.avoidance.episode import default_goal, episode_intruders
    from uavxai.dynamics.world import JSBSimWorld
    from uavxai.pipeline import planner_inputs

    av, world_box = scenario.avoidance, scenario.world
    goal = np.asarray(default_goal(scenario), dtype=float)
    specs = episode_intruders(scenario, seed, n_intruders)
    samples = max(1, round(av.decision_period_s * JSBSIM_SAMPLE_HZ))
    sample_s = av.decision_period_s / samples
    outcome, steps, min_sep, ms = "timeout", 0, math.inf, []
    with JSBSimWorld(scenario, intruders=specs, seed=seed) as world:
        world.command_ownship(alt_target_m=float(goal[2]))
        state = world.state()
        min_sep = state.min_separation()
        while steps < av.max_steps and outcome == "timeout":
            own, intruders = planner_inputs(state, world.ownship_command()["bank_cmd_rad"])
            decision = planner.plan(own, intruders, tuple(goal), step=steps)
            ms.append(decision.ms)
            world.command_ownship(
                bank_cmd_rad=decision.bank_cmd_rad, accel_cmd_mps2=decision.accel_mps2
            )
            steps += 1
            for _ in range(samples):
                prev = state
                world.advance(sample_s)
                state = world.state()
                if world.failure():
                    outcome = "out_of_bounds"  # the aircraft left its envelope: a failure
                    break
                flown = closest_approach(prev.pos[0], state.pos[0], prev.pos[1:], state.pos[1:])
                min_sep = min(min_sep, flown)
                p = state.pos[0]
                if flown < av.d_min_m:
                    outcome = "collision"
                elif not world_box.contains(float(p[0]), float(p[1]), float(p[2])):
                    outcome = "out_of_bounds"
                elif float(np.linalg.norm(p - goal)) < av.goal_radius_m:
                    outcome = "goal"
                if outcome != "timeout":
                    break
        flight_time = state.t
    return outcome, steps, min_sep, flight_time, ms


def closest_approach(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Smallest distance between the ownship moving p0 -> p1 and each intruder moving
    q0 -> q1 (N, 3), all linearly over the same interval; inf with no intruders."""
    if len(q0) == 0:
        return math.inf
    d0 = q0 - p0
    dv = (q1 - p1) - d0
    a = np.einsum("ij,ij->i", dv, dv)
    s = np.clip(-np.einsum("ij,ij->i", d0, dv) / np.where(a > 0, a, 1.0), 0.0, 1.0)
    return float(np.min(np.linalg.norm(d0 + s[:, None] * dv, axis=1)))


# ------------------------------------------------------------------------------- campaigns
Task = tuple[str, int, int]  # method, intruders, episode index


def campaign_tasks(methods: Sequence[str], intruders: Sequence[int], episodes: int) -> list[Task]:
    """Every (method, intruders, episode) of a campaign, in results order."""
    return [(m, n, i) for m in methods for n in intruders for i in range(episodes)]


def _init_worker() -> None:
    import torch

    torch.set_num_threads(1)


def _run_task(scenario: Scenario, task: Task, dynamics: str) -> dict:
    method, n, i = task
    row = run_campaign_episode(scenario, method, n, scenario.seed + i, dynamics)
    row["episode"] = i
    return row


def _ray_task(scenario: Scenario, task: Task, dynamics: str) -> dict:
    _init_worker()
    return _run_task(scenario, task, dynamics)


def run_campaign(
    scenario: Scenario,
    methods: Sequence[str],
    intruders: Sequence[int],
    episodes: int,
    *,
    dynamics: str = "kinematic",
    workers: int = 1,
    ray_address: str | None = None,
    on_done: Callable[[dict], None] | None = None,
) -> list[dict]:
    """Fly a campaign; returns the episode rows in (method, intruders, episode) order.

    ``on_done`` is called with each row as it finishes (for a progress bar).
    """
    _check(scenario, methods, intruders, episodes, dynamics, workers)
    tasks = campaign_tasks(methods, intruders, episodes)
    # Heavy tasks first (many intruders, tree search) so that workers finish together.
    order = sorted(range(len(tasks)), key=lambda k: -tasks[k][1])
    if ray_address is not None:
        rows = _run_ray(scenario, tasks, order, dynamics, ray_address, workers, on_done)
    elif workers == 1:
        rows = {}
        for k in order:
            rows[k] = _run_task(scenario, tasks[k], dynamics)
            if on_done:
                on_done(rows[k])
    else:
        rows = _run_pool(scenario, tasks, order, dynamics, workers, on_done)
    return [rows[k] for k in range(len(tasks))]


def _run_pool(scenario, tasks, order, dynamics, workers, on_done) -> dict[int, dict]:
    context = multiprocessing.get_context(
        "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    )
    rows: dict[int, dict] = {}
    with ProcessPoolExecutor(workers, mp_context=context, initializer=_init_worker) as pool:
        pending: dict[Future, int] = {
            pool.submit(_run_task, scenario, tasks[k], dynamics): k for k in order
        }
        try:
            while pending:
                done, _ = wait(pending, return_when=FIRST_COMPLETED)
                for f in done:
                    k = pending.pop(f)
                    rows[k] = f.result()
                    if on_done:
                        on_done(rows[k])
        except BaseException:
            for f in pending:
                f.cancel()
            raise
    return rows


def _run_ray(scenario, tasks, order, dynamics, address, workers, on_done) -> dict[int, dict]:
    try:
        import ray
    except ImportError:
        raise UserError(
            "--ray needs Ray, which is not installed: pip install 'uavxai[ray]'."
        ) from None
    started = False
    if not ray.is_initialized():
        os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
        try:
            if address == "local":
                ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
            else:
                ray.init(address=address, log_to_driver=False)
        except (ConnectionError, ValueError, RuntimeError) as exc:
            raise UserError(
                f"--ray {address}: cannot connect to a Ray cluster ({exc}). Use `local` to "
                "start one on this machine, `auto` for the cluster this machine is part of, or "
                "ray://HOST:PORT for a Ray client server."
            ) from None
        started = True
    try:
        remote = ray.remote(num_cpus=1)(_ray_task)
        scenario_ref = ray.put(scenario)
        pending = {remote.remote(scenario_ref, tasks[k], dynamics): k for k in order}
        rows: dict[int, dict] = {}
        while pending:
            done, _ = ray.wait(list(pending), num_returns=1)
            for ref in done:
                k = pending.pop(ref)
                rows[k] = ray.get(ref)
                if on_done:
                    on_done(rows[k])
        return rows
    finally:
        if started:
            ray.shutdown()


def _check(scenario, methods, intruders, episodes, dynamics, workers) -> None:
    bad = [m for m in methods if m not in METHODS]
    if bad or not methods:
        raise UserError(f"--methods {','.join(methods)}: allowed {', '.join(METHODS)}.")
    if not intruders or any(int(n) < 0 for n in intruders):
        raise UserError("--intruders: give one or more counts >= 0, e.g. 5,10,20,40.")
    if scenario.intruders.list is not None:
        raise UserError(
            f"scenario '{scenario.name}': intruders.list fixes the traffic, so --intruders "
            "cannot vary it; campaigns need random intruders (intruders.count)."
        )
    if episodes < 1:
        raise UserError(f"--episodes {episodes}: must be >= 1.")
    if dynamics not in DYNAMICS:
        raise UserError(f"--dynamics {dynamics}: allowed {', '.join(DYNAMICS)}.")
    if workers < 1:
        raise UserError(f"--workers {workers}: must be >= 1.")


# --------------------------------------------------------------------------------- results
def summarise(rows: Iterable[dict]) -> list[dict]:
    """One ``results.csv`` row per (method, intruders), in first-seen order."""
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["method"], int(r["intruders"])), []).append(r)
    results = []
    for (method, n), rs in groups.items():
        outcomes = [r["outcome"] for r in rs]
        seps = [float(r["min_separation_m"]) for r in rs]
        seps = [s for s in seps if math.isfinite(s)]
        ms = [m for r in rs for m in r.get("decision_ms", ())]
        if not ms:  # rows read back from episodes.csv carry only their own median
            ms = [float(r["decision_ms_p50"]) for r in rs]
        k = len(rs)
        results.append(
            {
                "method": method,
                "intruders": n,
                "episodes": k,
                "goal_rate": outcomes.count("goal") / k,
                "collision_rate": outcomes.count("collision") / k,
                "timeout_rate": outcomes.count("timeout") / k,
                "mean_steps": float(np.mean([int(r["steps"]) for r in rs])),
                "mean_min_separation_m": float(np.mean(seps)) if seps else math.nan,
                "decision_ms_p50": float(np.nanmedian(ms)) if ms else math.nan,
                "out_of_bounds_rate": outcomes.count("out_of_bounds") / k,
            }
        )
    return results


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[dict]) -> None:
    with path.open("w", newline="") as f:
        w = csv.writer(f)
        w.writerow(columns)
        for r in rows:
            w.writerow([_cell(r[c]) for c in columns])


def _cell(v):
    if isinstance(v, float):
        return f"{v:.6g}" if math.isfinite(v) else ("inf" if v > 0 else "nan")
    return v


PLOTS = (
    ("goal_rate", "goal rate", "goal_rate.png"),
    ("collision_rate", "collision rate", "collision_rate.png"),
    ("mean_steps", "mean steps (decisions)", "steps.png"),
)


# One look per method in every figure.
_STYLE = {
    "mcts": ("tab:blue", "o"),
    "mcts_fast": ("tab:orange", "s"),
    "exhaustive": ("tab:green", "^"),
    "dqn": ("tab:purple", "v"),
    "safe_dqn": ("tab:brown", "P"),
    "none": ("tab:red", "D"),
}


def plot_results(results: Sequence[dict], out: Path, title: str = "") -> list[Path]:
    """Goal rate, collision rate and steps against the intruder count, one line per method."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    methods = list(dict.fromkeys(r["method"] for r in results))
    paths = []
    for key, label, name in PLOTS:
        fig, ax = plt.subplots(figsize=(6.0, 4.0), dpi=120)
        for i, m in enumerate(methods):
            rs = sorted((r for r in results if r["method"] == m), key=lambda r: r["intruders"])
            colour, marker = _STYLE.get(m, (f"C{i % 10}", "o"))
            # Methods often tie (several at zero collisions): distinct markers and shrinking
            # sizes keep every one visible where lines lie on top of each other.
            ax.plot(
                [r["intruders"] for r in rs],
                [r[key] for r in rs],
                color=colour,
                marker=marker,
                markersize=9 - 1.0 * (i % 5),
                linewidth=2.2 - 0.25 * (i % 5),
                label=m,
            )
        ax.set_xlabel("intruders")
        ax.set_ylabel(label)
        if key.endswith("_rate"):
            ax.set_ylim(-0.02, 1.02)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=8)
        if title:
            ax.set_title(title, fontsize=9)
        fig.tight_layout()
        fig.savefig(out / name)
        plt.close(fig)
        paths.append(out / name)
    return paths


def merge_campaigns(sources: Sequence[str | Path], out: str | Path, title: str = "") -> list[dict]:
    """One campaign from several that ran different methods (or counts) of the same scenario
    and seeds, e.g. on different machines: their ``results.csv`` and ``episodes.csv`` rows
    side by side in ``out``, with the plots redrawn. A (method, intruders) pair found in two
    sources is an error, since their episodes would overlap."""
    out = Path(out)
    results: list[dict] = []
    episodes: list[dict] = []
    for src in map(Path, sources):
        for name, into in (("results.csv", results), ("episodes.csv", episodes)):
            if not (src / name).is_file():
                raise UserError(f"{src / name}: no such file; is {src} a campaign folder?")
            with (src / name).open() as f:
                into.extend(csv.DictReader(f))
    seen: set[tuple[str, int]] = set()
    for r in results:
        key = (r["method"], int(r["intruders"]))
        if key in seen:
            raise UserError(f"{key[0]} at {key[1]} intruders appears in more than one source.")
        seen.add(key)
        for k in RESULT_COLUMNS[1:]:
            r[k] = int(r[k]) if k in ("intruders", "episodes") else float(r[k])
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "results.csv", RESULT_COLUMNS, results)
    write_csv(out / "episodes.csv", EPISODE_COLUMNS, episodes)
    plot_results(results, out, title)
    return results


def evaluate_command(
    scenario: Scenario,
    methods: list[str],
    intruders: list[int],
    episodes: int,
    dynamics: str,
    workers: int,
    ray_address: str | None,
    out: Path,
) -> dict:
    """The `uavxai evaluate` command: run the campaign with a progress bar, write
    ``results.csv``, ``episodes.csv`` and the plots into ``out``; return a short report."""
    import torch
    from rich.console import Console

    from uavxai.progress import progress_bar

    torch.set_num_threads(1)
    _check(scenario, methods, intruders, episodes, dynamics, workers)
    # Load every planner once here: a missing checkpoint fails now, not in a worker.
    for m in methods:
        _planner(scenario, m)
    total = len(methods) * len(intruders) * episodes
    console = Console(stderr=True)
    wall0 = time.perf_counter()
    with progress_bar(console) as progress:
        bar = progress.add_task(f"{scenario.name} ({dynamics})", total=total)

        def done(row: dict) -> None:
            progress.update(
                bar, advance=1, description=f"{row['method']} x{row['intruders']}: {row['outcome']}"
            )

        rows = run_campaign(
            scenario,
            methods,
            intruders,
            episodes,
            dynamics=dynamics,
            workers=workers,
            ray_address=ray_address,
            on_done=done,
        )
    results = summarise(rows)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(out / "episodes.csv", EPISODE_COLUMNS, rows)
    write_csv(out / "results.csv", RESULT_COLUMNS, results)
    plots = plot_results(results, out, f"{scenario.name}, {dynamics}, {episodes} episodes")
    wall = time.perf_counter() - wall0
    console.print(_table(results))
    console.print(f"wrote {out / 'results.csv'}, {out / 'episodes.csv'} and {len(plots)} plots")
    return {"episodes": len(rows), "wall_s": wall, "results": results}


def _table(results: Sequence[dict]):
    from rich.table import Table

    t = Table("method", "intruders", "episodes", "goal", "collision", "timeout", "steps", "ms p50")
    for r in results:
        t.add_row(
            r["method"],
            str(r["intruders"]),
            str(r["episodes"]),
            f"{r['goal_rate']:.3f}",
            f"{r['collision_rate']:.3f}",
            f"{r['timeout_rate']:.3f}",
            f"{r['mean_steps']:.1f}",
            f"{r['decision_ms_p50']:.2f}",
        )
    return t
