"""A campaign's episodes flown: every (method, intruders, episode) task, in this process, in a
pool of local worker processes or as Ray tasks, finished rows taken over from a resumed
campaign's journal; and the campaign's settings checked before any flies.

The worker pool and Ray pickle the task functions (``_run_task``, ``_ray_task``,
``_remote_versions``) by their module path: they stay module-level functions of this module.
"""

from __future__ import annotations

import multiprocessing
import os
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from pathlib import Path

from uavxai.campaign.episode import run_campaign_episode
from uavxai.campaign.fleet import episode_folder, fleet_scenario, run_fleet_episode
from uavxai.errors import UserError
from uavxai.processes import interrupts_deferred
from uavxai.scenario import Scenario
from uavxai.sim.build import DYNAMICS as _DYNAMICS
from uavxai.vocabulary import avoidance_planners

DYNAMICS = tuple(_DYNAMICS)

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


def _run_task(
    scenario: Scenario, task: Task, dynamics: str, goal: Sequence[float], out: Path | None
) -> dict:
    method, n, i = task
    if scenario.fleet.size > 1:  # the fleet mission, as `uavxai run` flies it (JSBSim)
        folder = None if out is None else episode_folder(out, method, n, i)
        row = run_fleet_episode(scenario, method, n, scenario.seed + i, folder)
    else:
        row = run_campaign_episode(scenario, method, n, scenario.seed + i, dynamics, goal)
    row["episode"] = i
    return row


def _ray_task(
    scenario: Scenario, task: Task, dynamics: str, goal: Sequence[float], out: Path | None
) -> dict:
    _init_worker()
    return _run_task(scenario, task, dynamics, goal, out)


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
    out: Path | None = None,
) -> list[dict]:
    """Fly a campaign; returns the episode rows in (method, intruders, episode) order.

    ``on_done`` is called with each row as it finishes (for a progress bar). ``goal``: where
    every episode flies (None: :func:`uavxai.sim.spec.episode_goal` of ``scenario``).
    ``finished``: rows of tasks flown before (a resumed campaign's journal,
    :mod:`uavxai.journal`), taken as they are instead of flown again. ``out``: where a fleet
    campaign keeps each episode's run files (:func:`uavxai.campaign.fleet.episode_folder`;
    None: nowhere; with Ray, on the node that flew it).
    """
    from uavxai.sim.spec import episode_goal

    check_campaign(scenario, methods, intruders, episodes, dynamics, workers)
    tasks = campaign_tasks(methods, intruders, episodes)
    if scenario.fleet.size > 1:  # no goal: each member's station is planned per episode
        goal = ()
    common = (dynamics, tuple(episode_goal(scenario) if goal is None else goal), out)
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
            # address="local" starts a new instance even where a `ray start` of the past left
            # its address file behind (/tmp/ray/ray_current_cluster): without it, ray.init
            # joins that dead cluster and fails.
            ray.init(address="local", num_cpus=workers, include_dashboard=False,
                     log_to_driver=False)  # fmt: skip
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


def versions() -> dict[str, str]:
    """What must be the same wherever a campaign's episodes fly (the journal's header holds it,
    a Ray cluster's workers are checked against it)."""
    import jsbsim
    import torch

    from uavxai import __version__
    from uavxai.paths import source_digest

    return {"uavxai": __version__, "uavxai_sources": source_digest(),
            "jsbsim": jsbsim.__version__, "torch": torch.__version__}  # fmt: skip


def _remote_versions() -> dict[str, str]:
    try:
        return versions()
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
    mine = versions()
    if "missing" in theirs or theirs != mine:
        what = (f"lack the module {theirs['missing']}" if "missing" in theirs
                else f"have {theirs}, this driver {mine}")  # fmt: skip
        raise UserError(
            f"the Ray cluster's workers {what}. Install the same uavxai (the same code: "
            "uavxai_sources is a digest of its files), jsbsim and torch on every node (pip "
            "install uavxai[ray]==VERSION); see docs/cluster.md."
        )


def check_campaign(
    scenario: Scenario,
    methods: Sequence[str],
    intruders: Sequence[int],
    episodes: int,
    dynamics: str,
    workers: int,
) -> None:
    """A campaign's settings, refused with a message naming what is allowed before any flies."""
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
    if scenario.fleet.size > 1:
        if dynamics != "jsbsim":
            raise UserError(
                f"--dynamics {dynamics}: scenario '{scenario.name}' flies a fleet (fleet.size = "
                f"{scenario.fleet.size}), which flies in JSBSim only (the kinematic world has no "
                "members); give --dynamics jsbsim (docs/fleet.md, \"Fleet campaigns\")."
            )
        from uavxai.service.stage import check_planner_fits

        check_planner_fits(scenario)  # what `uavxai run` asks: each episode is its run
        for m in methods:  # every member flies the method: refused now, by name, if it cannot
            for n in intruders:
                fleet_scenario(scenario, m, n)
