"""`uavxai evaluate`: Monte Carlo campaigns of the avoidance stage (the paper's figures).

A campaign flies every method against every intruder count for ``episodes`` seeded episodes.
Episode ``i`` uses seed ``scenario.seed + i`` for every method and every count, so methods
meet the same encounters (the same start, goal and intruders) and any row of
``episodes.csv`` can be flown again alone::

    python -c "from uavxai.campaign import rerun_row; print(rerun_row('scenarios/demo.yaml', \
'mcts', 20, 17))"

(scenario file, method, intruders, seed; ``dynamics='jsbsim'`` for a JSBSim row; and
``goal=(goal_x, goal_y, goal_h)`` of the row for a campaign run from Python on a scenario
without ``ownship.goal`` whose seed was changed; `uavxai evaluate --seed N` flies to the goal
of the file's own seed, so its rows need no goal given).

Every episode is flown by the one episode engine (:func:`uavxai.sim.build.fly`), on the
kinematic encounter model or in JSBSim, with the planner's commands going straight to the
autopilot (no MAVLink, no recording); the goal is the scenario's (``ownship.goal``, else the
service point of the campaign's scenario at the seed its file names, whatever ``--seed``
says), the same for every episode and as ``uavxai run``.

A scenario with an ``encounters`` section (docs/scenario.md "encounters") flies episode ``i`` as
encounter ``i`` (:func:`uavxai.sim.encounter.fly_encounter`, seed ``scenario.seed + i``, one
intruder: intruder counts are refused); its rows gain ``ENCOUNTER_COLUMNS`` and its results the
weighted ``DAA_COLUMNS`` against ``none`` on the same seeds (docs/daa-metrics.md).

Episodes run in this process (``workers=1``), in local worker processes (``workers>1``; the
``forkserver`` context, one torch thread each) or as Ray tasks (``ray_address``: ``local``
starts a private Ray instance on this machine, ``auto`` joins the cluster this machine belongs
to, ``ray://host:port`` a remote one whose nodes have uavxai installed). Wherever an episode
runs, its numbers are the same: only the ``decision_ms`` timings differ.
"""

from __future__ import annotations

import contextlib
import csv
import io
import math
import multiprocessing
import os
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

import numpy as np

from uavxai.campaign_plots import plot_campaign
from uavxai.errors import UserError
from uavxai.outputs import cell_number, csv_cell, write_output
from uavxai.processes import interrupts_deferred
from uavxai.scenario import Scenario
from uavxai.sim.build import DYNAMICS as _DYNAMICS
from uavxai.vocabulary import OUTCOMES, Outcome, avoidance_planners

DYNAMICS = tuple(_DYNAMICS)
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
    "fdm_failure_rate",
    "nmac_rate",
    "nmac_rate_lo",
    "nmac_rate_hi",
    "collision_rate_lo",
    "collision_rate_hi",
    "risk_ratio",
    "risk_ratio_lo",
    "risk_ratio_hi",
    "collision_risk_ratio",
    "collision_risk_ratio_lo",
    "collision_risk_ratio_hi",
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
    "nmac",
    # The campaign's goal: one per campaign, written on every row so that pooled campaigns
    # (merge_campaigns) can check they flew the same encounters.
    "goal_x",
    "goal_y",
    "goal_h",
)
GOAL_COLUMNS = EPISODE_COLUMNS[-3:]
# Encounter campaigns (a scenario with `encounters`; docs/daa-metrics.md) add these:
# per episode (uavxai.sim.encounter), and per method the weighted DAA estimates of
# uavxai.daa_metrics.daa_summary against `none` on the same encounters.
ENCOUNTER_COLUMNS = ("weight", "hmd_m", "vmd_m", "lowc", "alert", "manoeuvre", "reversals")
# How each episode was flown (uavxai.sim.flight_quality), after the goal's columns; results
# gain their median / means. Files written before they existed are merged with them empty.
FLIGHT_COLUMNS = ("path_excess", "reversals_per_min", "bank_over_25_s")
FLIGHT_RESULTS = ("median_path_excess", "mean_reversals_per_min", "mean_bank_over_25_s")
DAA_RATES = (
    "nmac_prob", "nmac_risk_ratio", "induced_risk_ratio", "lowc_prob", "lowc_ratio",
    "alert_rate", "unnecessary_manoeuvre_rate",
)
DAA_COLUMNS = (
    *(f"{k}{end}" for k in DAA_RATES for end in ("", "_lo", "_hi")),
    "ci_check", "mean_reversals", "mean_path_excess",
)
# The columns whose values depend on the machine, not on the seed.
TIMING_COLUMNS = ("decision_ms_p50",)

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


def campaign_spec(
    scenario: Scenario,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
):
    """The episode a campaign of ``scenario`` flies at ``seed`` with ``n_intruders``: to the
    campaign's goal (None: the scenario's, :func:`uavxai.sim.spec.episode_goal` at the seed
    its file names, whatever the episode's seed: the same goal for every episode), no
    mission. An encounter campaign's one intruder is its encounter's (``fly_encounter``)."""
    from uavxai.sim.spec import episode_spec

    encounter = [] if scenario.encounters is not None else None
    return episode_spec(
        scenario, seed, n_intruders=n_intruders, dynamics=dynamics, goal=goal, intruders=encounter
    )


def run_campaign_episode(
    scenario: Scenario,
    method: str,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
) -> dict:
    """Fly one campaign episode on the episode engine (the commands go straight to the
    autopilot, no recording) and return its ``episodes.csv`` row (without ``episode``), plus
    ``decision_ms`` (every decision's planner time, for the pooled median). ``goal``: the
    campaign's goal (None: the scenario's, see :func:`campaign_spec`)."""
    from uavxai.sim.build import fly
    from uavxai.sim.flight_quality import FlightQuality

    if method not in avoidance_planners():
        raise UserError(f"method '{method}' is not one of {', '.join(avoidance_planners())}.")
    spec = campaign_spec(scenario, n_intruders, seed, dynamics, goal)
    extra: dict = {}
    start = (spec.start.x, spec.start.y, spec.start.h)
    quality = FlightQuality(None if spec.mission else (start, spec.goal))
    if scenario.encounters is not None:  # episode i is encounter i, with its one intruder
        from uavxai.sim.encounter import fly_encounter

        r, rec, _ = fly_encounter(scenario, _planner(scenario, method), seed, dynamics, quality)
        n_intruders = 1
        extra = {
            "weight": float(rec.weight),
            "hmd_m": round(rec.hmd_m, 3),
            "vmd_m": round(rec.vmd_m, 3),
            "lowc": int(rec.lowc),
            "alert": int(rec.alert),
            "manoeuvre": int(rec.manoeuvre),
            "reversals": int(rec.reversals),
        }
    else:
        r = fly(spec, _planner(scenario, method), observers=[quality])
    if r.outcome is Outcome.INTERRUPTED:
        # a signal to this process: the campaign stops here (its caller keeps the finished
        # episodes), and a flight cut short is no episode of its results
        raise KeyboardInterrupt("episode interrupted")
    ms = r.decision_ms
    return {
        "method": method,
        "intruders": int(n_intruders),
        "seed": int(seed),
        "outcome": r.outcome.value,
        "steps": int(r.steps),
        "min_separation_m": round(float(r.min_separation_m), 3)
        if math.isfinite(r.min_separation_m)
        else math.inf,
        "flight_time_s": round(float(r.flight_time_s), 3),
        "nmac": int(r.nmac),
        "decision_ms_p50": round(float(np.median(ms)), 4) if ms else math.nan,
        **{k: round(float(v), 3) for k, v in zip(GOAL_COLUMNS, spec.goal, strict=True)},
        **quality.result().row(),
        **extra,
        "decision_ms": ms,
    }


def rerun_row(
    scenario_path: str | Path,
    method: str,
    n_intruders: int,
    seed: int,
    dynamics: str = "kinematic",
    goal: Sequence[float] | None = None,
) -> dict:
    """Fly one row of an ``episodes.csv`` again: its scenario file, method, intruders, seed and
    (for a scenario without ``ownship.goal`` flown with another ``--seed``) the row's goal."""
    from uavxai.scenario import load_scenario

    scenario = load_scenario(scenario_path)
    row = run_campaign_episode(scenario, method, n_intruders, seed, dynamics, goal)
    row.pop("decision_ms")
    return row


# ------------------------------------------------------------------------------- campaigns
Task = tuple[str, int, int]  # method, intruders, episode index


def campaign_tasks(methods: Sequence[str], intruders: Sequence[int], episodes: int) -> list[Task]:
    """Every (method, intruders, episode) of a campaign, in results order."""
    return [(m, n, i) for m in methods for n in intruders for i in range(episodes)]


def _init_worker() -> None:
    import torch

    torch.set_num_threads(1)


def _init_pool_worker(start_method: str, owner: int) -> None:
    """A local pool's worker: it dies with its parent (the forkserver, or with ``spawn`` the
    campaign's process ``owner``) and leaves SIGINT and SIGTERM to the campaign's process,
    which keeps the finished episodes and kills it."""
    from uavxai.forkserver_preload import FORKSERVER_PID
    from uavxai.processes import die_with_parent, ignore_interrupts

    if start_method == "forkserver":  # the pid is there if the forkserver is ours
        parent = int(os.environ[FORKSERVER_PID]) if FORKSERVER_PID in os.environ else None
    else:
        parent = owner
    die_with_parent(parent)
    ignore_interrupts()
    _init_worker()


def _run_task(scenario: Scenario, task: Task, dynamics: str, goal: Sequence[float]) -> dict:
    method, n, i = task
    row = run_campaign_episode(scenario, method, n, scenario.seed + i, dynamics, goal)
    row["episode"] = i
    return row


def _ray_task(scenario: Scenario, task: Task, dynamics: str, goal: Sequence[float]) -> dict:
    _init_worker()
    return _run_task(scenario, task, dynamics, goal)


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
    goal: Sequence[float] | None = None,
    finished: Mapping[tuple[str, int, int], dict] | None = None,
) -> list[dict]:
    """Fly a campaign; returns the episode rows in (method, intruders, episode) order.

    ``on_done`` is called with each row as it finishes (for a progress bar). ``goal``: where
    every episode flies (None: :func:`uavxai.sim.spec.episode_goal` of ``scenario``).
    ``finished``: rows of tasks flown before (a resumed campaign's journal,
    :mod:`uavxai.journal`), taken as they are instead of flown again.
    """
    from uavxai.sim.spec import episode_goal

    _check(scenario, methods, intruders, episodes, dynamics, workers)
    tasks = campaign_tasks(methods, intruders, episodes)
    common = (dynamics, tuple(episode_goal(scenario) if goal is None else goal))
    finished = finished or {}
    # Heavy tasks first (many intruders, tree search) so that workers finish together.
    order = sorted(
        (k for k in range(len(tasks)) if tasks[k] not in finished), key=lambda k: -tasks[k][1]
    )
    if ray_address is not None:
        rows = _run_ray(scenario, tasks, order, common, ray_address, workers, on_done)
    elif workers == 1:
        rows = {}
        for k in order:
            rows[k] = _run_task(scenario, tasks[k], *common)
            if on_done:
                on_done(rows[k])
    else:
        rows = _run_pool(scenario, tasks, order, common, workers, on_done)
    return [rows[k] if k in rows else finished[t] for k, t in enumerate(tasks)]


_POLL_S = 0.25  # how long a signal waits to stop a pooled campaign, s


def _run_pool(scenario, tasks, order, common, workers, on_done) -> dict[int, dict]:
    from uavxai import forkserver_preload

    method = "forkserver" if "forkserver" in multiprocessing.get_all_start_methods() else "spawn"
    context = multiprocessing.get_context(method)
    if method == "forkserver":
        forkserver_preload.start(context)
    rows: dict[int, dict] = {}
    pool = ProcessPoolExecutor(
        workers, mp_context=context, initializer=_init_pool_worker,
        initargs=(method, os.getpid()),
    )  # fmt: skip
    pending: dict[Future, int] = {
        pool.submit(_run_task, scenario, tasks[k], *common): k for k in order
    }
    try:
        # A signal is noted while the pool runs and raised between two waits, never inside
        # concurrent.futures: a KeyboardInterrupt raised in `wait` (which takes every future's
        # lock in turn) could leave a future's lock held by this thread, and the pool's own
        # thread, cancelling that future, then waited for it for ever at exit (a campaign
        # that saved its files and never ended, under a burst of SIGTERMs).
        with interrupts_deferred() as caught:
            while pending and not caught:
                done, _ = wait(pending, timeout=_POLL_S, return_when=FIRST_COMPLETED)
                for f in done:
                    k = pending.pop(f)
                    rows[k] = f.result()
                    if on_done:
                        on_done(rows[k])
        if caught:  # delivered above as the handler does; one that ignores it stops us too
            raise KeyboardInterrupt(f"signal {caught[0]}")
    except BaseException:
        # Interrupted (Ctrl-C, SIGTERM) or failed: stop the workers now, not after their
        # running episodes (they ignore SIGTERM: killed); the caller keeps what finished.
        with interrupts_deferred():  # a second signal must not leave them running
            processes = list(getattr(pool, "_processes", {}).values())
            manager = getattr(pool, "_executor_manager_thread", None)
            pool.shutdown(wait=False, cancel_futures=True)
            for p in processes:
                p.kill()
            # Its thread sees them die and tidies up; let it finish before the interpreter's
            # exit wakes it (Python 3.11 races there: "Bad file descriptor" at exit).
            if manager is not None:
                manager.join(timeout=10)
        raise
    pool.shutdown()
    return rows


def _run_ray(scenario, tasks, order, common, address, workers, on_done) -> dict[int, dict]:
    try:
        import ray
    except ImportError:
        raise UserError(
            "--ray needs Ray, which is not installed: pip install 'uavxai[ray]'."
        ) from None
    started = False
    if not ray.is_initialized():
        _ray_connect(ray, address, workers)
        started = True
    try:
        _check_workers(ray)
        remote = ray.remote(num_cpus=1)(_ray_task)
        scenario_ref = ray.put(scenario)
        pending = {remote.remote(scenario_ref, tasks[k], *common): k for k in order}
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


def _ray_connect(ray, address: str, workers: int) -> None:
    """Start a private Ray (``local``) or join a cluster, with errors a user can act on."""
    import logging

    os.environ.setdefault("RAY_USAGE_STATS_ENABLED", "0")
    if address != "local" and workers > 1:
        logging.getLogger(__name__).warning(
            "--workers %d is ignored with --ray %s: the cluster's CPUs decide how many "
            "episodes fly at once", workers, address)  # fmt: skip
    try:
        if address == "local":
            ray.init(num_cpus=workers, include_dashboard=False, log_to_driver=False)
        else:
            ray.init(address=address, log_to_driver=False)
    except (ConnectionError, ValueError, RuntimeError) as exc:
        text = str(exc)
        if "auth" in text.lower() or "token" in text.lower():
            raise UserError(
                f"--ray {address}: the cluster refused this driver's authentication ({text}). "
                "Ray 2.60 turns token authentication on after its first local start: run with "
                "RAY_AUTH_MODE=token and the cluster's token (the file Ray wrote under the "
                "home folder of the machine that started the head, or RAY_AUTH_TOKEN), or "
                "start the head with authentication off. See docs/cluster.md."
            ) from None
        raise UserError(
            f"--ray {address}: cannot connect to a Ray cluster ({text}). Use `local` to "
            "start one on this machine, `auto` for the cluster this machine is part of, or "
            "ray://HOST:PORT for a Ray client server (pip install 'uavxai[ray]' brings the "
            "client). See docs/cluster.md."
        ) from None


def _versions() -> dict[str, str]:
    import jsbsim
    import torch

    from uavxai import __version__
    from uavxai.paths import source_digest

    return {"uavxai": __version__, "uavxai_sources": source_digest(),
            "jsbsim": jsbsim.__version__, "torch": torch.__version__}  # fmt: skip


def _remote_versions() -> dict[str, str]:
    try:
        return _versions()
    except ModuleNotFoundError as exc:  # a worker without uavxai (or its dependencies)
        return {"missing": str(exc.name)}


def _check_workers(ray) -> None:
    """The cluster's workers must have the same uavxai, jsbsim and torch as this driver, or
    episodes would fail (or fly differently) there; say what is missing before flying."""
    try:
        theirs = ray.get(ray.remote(num_cpus=1)(_remote_versions).remote(), timeout=300)
    except Exception as exc:  # noqa: BLE001 - a worker that cannot even unpickle the task
        raise UserError(
            f"the Ray cluster's workers cannot run uavxai's tasks ({type(exc).__name__}: "
            f"{str(exc)[:200]}). Install uavxai (pip install uavxai[ray]) on every node, in "
            "the same version as here; see docs/cluster.md."
        ) from None
    mine = _versions()
    if "missing" in theirs or theirs != mine:
        what = (f"lack the module {theirs['missing']}" if "missing" in theirs
                else f"have {theirs}, this driver {mine}")  # fmt: skip
        raise UserError(
            f"the Ray cluster's workers {what}. Install the same uavxai (the same code: "
            "uavxai_sources is a digest of its files), jsbsim and torch on every node (pip "
            "install uavxai[ray]==VERSION); see docs/cluster.md."
        )


def _check(scenario, methods, intruders, episodes, dynamics, workers) -> None:
    bad = [m for m in methods if m not in avoidance_planners()]
    if bad or not methods:
        raise UserError(
            f"--methods {','.join(methods)}: allowed {', '.join(avoidance_planners())}."
        )
    if not intruders or any(int(n) < 0 for n in intruders):
        raise UserError("--intruders: give one or more counts >= 0, e.g. 5,10,20,40.")
    if scenario.encounters is not None and list(intruders) != [1]:
        raise UserError(
            f"scenario '{scenario.name}' flies encounters: each episode has its sampled "
            "encounter's one intruder, so intruder counts cannot vary it (leave --intruders out)."
        )
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
    """One ``results.csv`` row per (method, intruders), in first-seen order.

    Rates come with their 95 % Wilson interval; the risk ratio is NMAC(method) / NMAC(none)
    on the same encounters (the detect-and-avoid field's figure of merit), with a paired
    bootstrap interval; ``collision_risk_ratio`` the same for collisions. Both are empty
    (nan) when ``none`` was not flown at that intruder count."""
    rows = list(rows)
    groups: dict[tuple[str, int], list[dict]] = {}
    for r in rows:
        groups.setdefault((r["method"], int(r["intruders"])), []).append(r)
    out = [_summary_row(method, n, rs, groups.get(("none", n))) for (method, n), rs in
           groups.items()]  # fmt: skip
    if rows and all(_is_encounter_row(r) for r in rows):
        for row in out:
            n = row["intruders"]
            row.update(_daa_row(row["method"], groups[(row["method"], n)], groups.get(("none", n))))
    return out


def _is_encounter_row(r: dict) -> bool:
    """A row of an encounter campaign (it has a weight)."""
    return str(r.get("weight", "")) != ""


def columns_of(rows: Sequence[dict]) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """The (episodes.csv, results.csv) columns of a campaign's rows: with the encounter
    columns when every row is an encounter's."""
    if rows and all(_is_encounter_row(r) for r in rows):
        return (EPISODE_COLUMNS + FLIGHT_COLUMNS + ENCOUNTER_COLUMNS,
                RESULT_COLUMNS + FLIGHT_RESULTS + DAA_COLUMNS)  # fmt: skip
    return EPISODE_COLUMNS + FLIGHT_COLUMNS, RESULT_COLUMNS + FLIGHT_RESULTS


def _daa_row(method: str, rs: list[dict], baseline: list[dict] | None) -> dict:
    """The weighted DAA columns of one method against ``none`` on the encounters (seeds) both
    flew (uavxai.daa_metrics.daa_summary); nan (and ci_check empty) without ``none``."""
    from uavxai.daa_metrics import daa_summary

    row: dict = {k: math.nan for k in DAA_COLUMNS}
    row["ci_check"] = ""
    if baseline is None:
        return row

    def by_seed(group: list[dict]) -> dict[int, dict]:
        return {int(r["seed"]): r for r in group}

    mine, base = by_seed(rs), by_seed(baseline)
    seeds = sorted(set(mine) & set(base))
    if not seeds:
        return row

    def columns(group: dict[int, dict]) -> dict[str, np.ndarray]:
        def col(key: str) -> np.ndarray:
            return np.array([cell_number(group[s][key]) for s in seeds])

        cols = {k: col(k) > 0.5 for k in ("nmac", "lowc", "alert", "manoeuvre")}
        cols.update(reversals=col("reversals"), path_excess=col("path_excess"))
        return cols

    weights = np.array([float(base[s]["weight"]) for s in seeds])
    theirs = np.array([float(mine[s]["weight"]) for s in seeds])
    if not np.allclose(weights, theirs, rtol=1e-6, atol=0.0):
        raise UserError(
            f"{method}: its encounters' weights differ from none's on the same seeds; these "
            "episodes were not flown on the same encounters (another scenario?)."
        )
    per = {"none": columns(base)}
    if method != "none":
        per[method] = columns(mine)
    est = daa_summary(per, weights)[method]
    row.update({k: est[k] for k in DAA_COLUMNS if k in est})
    row["mean_reversals"], row["mean_path_excess"] = est["reversals"], est["path_excess"]
    return row


def _events(rs: Sequence[dict], key: str) -> dict[int, bool]:
    """Per encounter (seed): did it happen? ``key`` 'collision' or 'nmac'."""
    if key == "collision":
        return {int(r["seed"]): r["outcome"] == "collision" for r in rs}
    return {int(r["seed"]): bool(int(float(r.get("nmac", 0)))) for r in rs}


def _summary_row(method: str, n: int, rs: list[dict], baseline: list[dict] | None) -> dict:
    from uavxai.metrics import rate, risk_ratio

    outcomes = [r["outcome"] for r in rs]
    seps = [float(r["min_separation_m"]) for r in rs]
    seps = [s for s in seps if math.isfinite(s)]
    ms = [m for r in rs for m in r.get("decision_ms", ())]
    if not ms:  # rows read back from episodes.csv carry only their own median
        ms = [float(r["decision_ms_p50"]) for r in rs]
    k = len(rs)
    row = {
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
        "fdm_failure_rate": outcomes.count("fdm_failure") / k,
    }
    for key, prefix in (("collision", "collision_rate"), ("nmac", "nmac_rate")):
        r = rate(list(_events(rs, key).values()))
        row[prefix], row[f"{prefix}_lo"], row[f"{prefix}_hi"] = r.rate, r.lo, r.hi
    for key, prefix in (("nmac", "risk_ratio"), ("collision", "collision_risk_ratio")):
        row[prefix] = row[f"{prefix}_lo"] = row[f"{prefix}_hi"] = math.nan
        if baseline is not None:
            mine, base = _events(rs, key), _events(baseline, key)
            seeds = sorted(set(mine) & set(base))  # the same encounters only
            rr = risk_ratio([mine[s] for s in seeds], [base[s] for s in seeds])
            row[prefix], row[f"{prefix}_lo"], row[f"{prefix}_hi"] = rr.ratio, rr.lo, rr.hi
    row.update(_flight_results(rs))
    return row


def _flight_results(rs: list[dict]) -> dict:
    """The median path excess (over the episodes that made progress) and the mean reversal
    rate and steep-bank time of one results row; nan where no episode has the number."""

    def finite(key: str) -> np.ndarray:
        v = np.array([cell_number(r.get(key)) for r in rs])
        return v[np.isfinite(v)]

    excess, per_min, steep = (finite(k) for k in FLIGHT_COLUMNS)
    return {
        "median_path_excess": float(np.median(excess)) if excess.size else math.nan,
        "mean_reversals_per_min": float(per_min.mean()) if per_min.size else math.nan,
        "mean_bank_over_25_s": float(steep.mean()) if steep.size else math.nan,
    }


def write_csv(path: Path, columns: Sequence[str], rows: Iterable[dict]) -> None:
    """A CSV file written whole (temporary file + rename, never through a link); text cells a
    spreadsheet would run as a formula are made inert (:func:`uavxai.outputs.csv_cell`)."""
    buf = io.StringIO(newline="")
    w = csv.writer(buf)
    w.writerow(columns)
    for r in rows:
        w.writerow([csv_cell(_cell(r[c])) for c in columns])
    write_output(path, buf.getvalue())


def _cell(v):
    if isinstance(v, float):
        if math.isnan(v):
            return ""  # not defined (e.g. a risk ratio without `none` flown)
        return f"{v:.6g}" if math.isfinite(v) else ("inf" if v > 0 else "-inf")
    return v


def merge_campaigns(sources: Sequence[str | Path], out: str | Path, title: str = "") -> list[dict]:
    """One campaign from several of the same scenario and dynamics: other methods, other
    intruder counts, or more seeds of the same ones (a campaign extended later, or split over
    machines). The episodes are pooled and every ``results.csv`` row is computed again from
    them, so a risk ratio pairs a method with ``none`` on every seed both flew, whichever source
    flew it. The same (method, intruders, seed) in two sources is an error: it would count twice.

    ``decision_ms_p50`` is the source's when one source flew the whole row; a pooled row has
    only each episode's median to go on and takes the median of those."""
    out = Path(out)
    episodes: list[dict] = []
    flown_by: dict[tuple[str, int, int], Path] = {}
    p50: dict[tuple[str, int], float] = {}
    goals: dict[tuple[str, ...], Path] = {}
    for src in map(Path, sources):
        # files written before the goal was recorded lack its columns, and are taken on trust
        rows = _read_rows(src / "episodes.csv", EPISODE_COLUMNS[: -len(GOAL_COLUMNS)])
        rows = [_checked_row(r, src / "episodes.csv", i) for i, r in enumerate(rows, start=2)]
        for i, r in enumerate(rows, start=2):
            try:
                if _is_encounter_row(r):  # an encounter campaign's columns
                    if not 0 < float(r["weight"]) < math.inf:
                        raise ValueError
                    for column in ENCOUNTER_COLUMNS[1:]:
                        cell_number(r.get(column))
            except (TypeError, ValueError):
                raise UserError(
                    f"{src / 'episodes.csv'} line {i}: in an encounter campaign "
                    f"{', '.join(ENCOUNTER_COLUMNS)} must be numbers, the weight > 0."
                ) from None
        for r in rows:
            for column in FLIGHT_COLUMNS:  # not in files written before they existed
                r.setdefault(column, "")
            key = (r["method"], r["intruders"], r["seed"])
            if key in flown_by:
                raise UserError(
                    f"{key[0]} at {key[1]} intruders, seed {key[2]}: flown in both "
                    f"{flown_by[key]} and {src}; merge campaigns of different seeds, methods or "
                    "intruder counts."
                )
            flown_by[key] = src
            goal = tuple(r[k] for k in GOAL_COLUMNS)
            if any(g != "" for g in goal):
                goals.setdefault(goal, src)
        episodes.extend(rows)
        for r in _read_rows(src / "results.csv", RESULT_COLUMNS):
            # garbage timing: nothing to keep, the row's own median of medians stands
            with contextlib.suppress(ValueError, OverflowError):
                ms = float(r["decision_ms_p50"] or "nan")
                if math.isfinite(ms) and ms >= 0:
                    p50[(r["method"], int(r["intruders"]))] = ms
    if len({_is_encounter_row(r) for r in episodes}) > 1:
        raise UserError(
            "these campaigns mix encounter campaigns (episodes.csv with weight, hmd_m, ...) and "
            "random-traffic ones; merge campaigns of the same scenario."
        )
    if len(goals) > 1:
        what = "; ".join(f"{src}: ({', '.join(map(str, g))})" for g, src in goals.items())
        raise UserError(
            f"these campaigns flew to different goals ({what}), so the same seed is not the same "
            "encounter; a scenario without ownship.goal flies to the service point of its "
            "file's seed (`uavxai evaluate --seed N` keeps it; a campaign written before that, "
            "or run from Python on a scenario whose seed was changed, has another)."
        )
    sources_of: dict[tuple[str, int], set[Path]] = {}
    for (m, n, _), src in flown_by.items():
        sources_of.setdefault((m, n), set()).add(src)
    results = summarise(episodes)
    for r in results:
        if len(sources_of[(r["method"], r["intruders"])]) == 1:
            r["decision_ms_p50"] = p50.get((r["method"], r["intruders"]), r["decision_ms_p50"])
    with interrupts_deferred():  # a signal now waits for the files: they end whole
        out.mkdir(parents=True, exist_ok=True)
        episode_columns, result_columns = columns_of(episodes)
        write_csv(out / "results.csv", result_columns, results)
        write_csv(out / "episodes.csv", episode_columns, episodes)
        plot_campaign(results, out, title)
    return results


MAX_STEPS = 10**7  # decisions in one episode: far beyond any scenario's max_steps
MAX_SEED = 2**31 - 1
MAX_INTRUDERS = 10_000


def _checked_row(r: dict, path: Path, line: int) -> dict:
    """One ``episodes.csv`` row of a source campaign, every value within what a campaign
    writes, typed (so that the merged files hold numbers, not the source's text)."""

    def bad(column: str, allowed: str) -> UserError:
        value = str(r.get(column))
        shown = value if len(value) <= 40 else value[:37] + "..."
        return UserError(
            f"{path} line {line}: {column} {shown!r} is not allowed; {column} must be {allowed}. "
            "The file was not written by `uavxai evaluate` as it stands."
        )

    def number(column: str, lo: float, hi: float, allowed: str, empty=None, whole=False):
        text = (r.get(column) or "").strip()
        if text == "" and empty is not None:
            return empty
        try:
            v = float(text)
        except ValueError:
            raise bad(column, allowed) from None
        if math.isnan(v) or not lo <= v <= hi or (whole and v != int(v)):
            raise bad(column, allowed)
        return int(v) if whole else v

    out = dict(r)
    if r.get("method") not in avoidance_planners():
        raise bad("method", f"a planner name, one of {', '.join(avoidance_planners())}")
    if r.get("outcome") not in OUTCOMES:
        raise bad("outcome", f"one of {', '.join(OUTCOMES)}")
    out["intruders"] = number("intruders", 0, MAX_INTRUDERS,
                              f"a whole number from 0 to {MAX_INTRUDERS}", whole=True)  # fmt: skip
    out["episode"] = number("episode", 0, MAX_SEED, "a whole number >= 0", whole=True)
    out["seed"] = number("seed", 0, MAX_SEED, f"a whole number from 0 to {MAX_SEED}", whole=True)
    out["steps"] = number("steps", 0, MAX_STEPS, f"a whole number from 0 to {MAX_STEPS}",
                          whole=True)  # fmt: skip
    out["min_separation_m"] = number(
        "min_separation_m", 0, math.inf, "a distance >= 0 in metres ('inf': no intruder)"
    )
    out["flight_time_s"] = number("flight_time_s", 0, 1e9, "a time >= 0 in seconds")
    out["nmac"] = number("nmac", 0, 1, "0 or 1", whole=True)
    out["decision_ms_p50"] = number(
        "decision_ms_p50", 0, 1e9, "a time >= 0 in milliseconds, or empty", empty=math.nan
    )
    for column in GOAL_COLUMNS:  # files written before the goal was recorded lack it
        out[column] = number(column, -1e7, 1e7, "a coordinate in metres, or empty", empty="")
    return out


def _read_rows(path: Path, columns: Sequence[str]) -> list[dict]:
    """A campaign file's rows, refused with a clear message if it is not one."""
    if not path.is_file():
        raise UserError(f"{path}: no such file; is {path.parent} a campaign folder?")
    try:
        with path.open(newline="") as f:
            reader = csv.DictReader(f)
            rows = list(reader)
            missing = [c for c in columns if c not in (reader.fieldnames or ())]
    except (OSError, UnicodeDecodeError, csv.Error) as exc:
        raise UserError(f"{path}: cannot read it as a campaign file ({exc}).") from None
    if missing:
        raise UserError(
            f"{path}: not a campaign file of this uavxai, it lacks the columns "
            f"{', '.join(missing)}."
        )
    return rows


def _campaign_goal(scenario: Scenario, goal: Sequence[float] | None, console) -> tuple:
    """Where every episode flies, said on ``console``: ``goal``, or None: the scenario's
    (``ownship.goal``, else its service point). `uavxai evaluate --seed N` passes the goal of
    the scenario file's own seed, so that a campaign extended with another seed flies to the
    same goal and merges with the first."""
    from uavxai.sim.spec import episode_goal

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
    ``out``; a short report back. ``goal``: see :func:`_campaign_goal`; ``resume``: fly only
    what an interrupted run of the same campaign did not journal in ``out``."""
    import torch
    from rich.console import Console

    from uavxai.journal import Journal, campaign_header, read_journal
    from uavxai.progress import progress_bar

    torch.set_num_threads(1)
    _check(scenario, methods, intruders, episodes, dynamics, workers)
    # Load every planner once here: a missing checkpoint fails now, not in a worker.
    for m in methods:
        _planner(scenario, m)
    total = len(methods) * len(intruders) * episodes
    # Piped output gets a wide table rather than column names cut to fit 80 characters.
    console = Console(stderr=True, width=None if sys.stderr.isatty() else 200)
    wall0 = time.perf_counter()
    goal = _campaign_goal(scenario, goal, console)
    header = campaign_header(scenario, methods, intruders, episodes, dynamics, goal, _versions())
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
            )
        except KeyboardInterrupt:
            _keep_finished(finished, out, console)
            raise
        finally:
            journal.close()
    results, plots = _save(rows, out, f"{scenario.name}, {dynamics}, {episodes} episodes")
    wall = time.perf_counter() - wall0
    console.print(results_table(results))
    if scenario.encounters is not None:
        console.print(daa_table(results))
    console.print(f"wrote {out / 'results.csv'}, {out / 'episodes.csv'} and {len(plots)} plots")
    return {"episodes": len(rows), "wall_s": wall, "results": results}


def _save(rows: list[dict], out: Path, title: str) -> tuple[list[dict], list[Path]]:
    """A finished campaign's ``episodes.csv``, ``results.csv`` and plots; a signal that comes
    meanwhile waits for them to be whole. Its results and the plots' paths."""
    with interrupts_deferred():
        results = summarise(rows)
        out.mkdir(parents=True, exist_ok=True)
        episode_columns, result_columns = columns_of(rows)
        write_csv(out / "episodes.csv", episode_columns, rows)
        write_csv(out / "results.csv", result_columns, results)
        return results, plot_campaign(results, out, title)


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
        out.mkdir(parents=True, exist_ok=True)
        episode_columns, result_columns = columns_of(rows)
        write_csv(out / "episodes.csv", episode_columns, rows)
        write_csv(out / "results.csv", result_columns, summarise(rows))
        console.print(
            f"interrupted: kept the {len(rows)} finished episodes in {out / 'episodes.csv'} "
            f"and {out / 'results.csv'}; the same command with --resume flies the others"
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
    """The weighted detect-and-avoid columns of an encounter campaign, one row per method."""
    from rich.table import Table

    def ci(r: dict, key: str) -> str:
        v, lo, hi = (cell_number(r.get(k)) for k in (key, f"{key}_lo", f"{key}_hi"))
        return "-" if math.isnan(v) else f"{v:.3g} [{lo:.3g}, {hi:.3g}]"

    t = Table("method", "encounters", "P(NMAC)", "NMAC risk ratio", "induced", "P(LoWC)",
              "LoWC ratio", "alert rate", "unnecessary manoeuvre", "reversals", "path excess",
              "CI check", title="detect and avoid (weighted, 95 % bootstrap)")  # fmt: skip
    for r in results:
        t.add_row(r["method"], str(r["episodes"]), ci(r, "nmac_prob"), ci(r, "nmac_risk_ratio"),
                  ci(r, "induced_risk_ratio"), ci(r, "lowc_prob"), ci(r, "lowc_ratio"),
                  ci(r, "alert_rate"), ci(r, "unnecessary_manoeuvre_rate"),
                  f"{cell_number(r.get('mean_reversals')):.2f}",
                  f"{cell_number(r.get('mean_path_excess')):.4f}", str(r.get("ci_check", "")))
    return t
