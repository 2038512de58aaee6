"""The service-point stage: where the UAV should hover and with what power per user.

``plan_service(scenario)`` draws the users (``channel.draw_users``: the scenario's positions, or
uniform in the region from ``default_rng(seed)``), runs the chosen planner and reports the
link at the chosen point. Planners:

- ``d3qn`` — with ``service.checkpoint: null`` the shipped universal D3QN
  (``universal.py``: one model for any K from 2 to 20, both access modes, all environments)
  is flown greedily, zero-shot (no training on the layout), and its best visited point is
  polished by ``universal.refine`` (lattice neighbours and power levels, best improvement);
  ``extras`` report the D3QN alone (``d3qn_alone_objective``) beside what is returned. A
  ``service.checkpoint`` written by ``uavxai train --stage universal`` is used the same
  way; one written by ``uavxai train`` (a per-layout model) is flown greedily as trained.
- ``dqn`` — the same with the shipped DQN ablation (no dueling, no double targets).
- ``random`` — ``service.steps`` random lattice points with random power levels.
- ``grid`` — the exact optimum over the lattice and the discrete power levels.

Positions are ranked by the fading-free objective (fading averages out over the time the UAV
serves there). ``service.platform`` says which: ``hover`` is the paper's, the objective at the
point itself; ``orbit`` (the default: a fixed wing circles the point) is the objective averaged
over the loiter orbit the mission will fly about the point, power fixed over the orbit
(``uavxai.service.orbit``): ``grid`` is then the exact orbit optimum, ``random`` ranks its
draws by it, and the learned planners fly their (hover-trained) network and refine and set
the power on it. A per-layout model from ``uavxai train`` is flown as trained either way.

``sinr_db``/``rate_bps``/``objective`` are the hover point's values, fading-free;
``ergodic_*`` average over fading; ``orbit_*`` are the orbit's fading-free averages at the
chosen point with the chosen power (reported whatever the platform, so a hover placement can
be judged by what an orbiting aircraft would give there).
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
import torch

from uavxai.comms.channel import Channel
from uavxai.errors import CheckpointError, UserError
from uavxai.learning import checkpoint
from uavxai.paths import service_checkpoints_dir
from uavxai.scenario import Scenario
from uavxai.service import d3qn, universal
from uavxai.service.grid import Progress, solve_grid
from uavxai.service.orbit import OrbitObjective, solve_grid_orbit
from uavxai.service.orbit_rate import orbit_average
from uavxai.service.random_search import random_search
from uavxai.service.service_env import ServiceEnv, levels_to_power

ERGODIC_DRAWS = 2000
PLANNERS = ("d3qn", "dqn", "random", "grid")


@dataclass
class ServiceResult:
    planner: str
    users: np.ndarray  # (K, 3)
    service_point: np.ndarray  # (3,)
    levels: np.ndarray  # (K,) integer power levels
    power_w: np.ndarray  # (K,)
    sinr_db: np.ndarray  # (K,), -inf for unserved users
    rate_bps: np.ndarray  # (K,)
    sum_rate_bps: float
    qos_satisfied: int
    objective: float  # R / 2^lambda, fading-free
    visited: np.ndarray  # (T, 3): the search path (or the points evaluated)
    naive_objective: float  # users' centroid at 100 m, equal power
    ergodic_sum_rate_bps: float
    ergodic_objective: float
    wall_s: float
    extras: dict[str, Any] = field(default_factory=dict)

    def to_summary(self) -> dict[str, Any]:
        """Plain JSON-serialisable fields (README's service fields, plus extras)."""
        return {
            "planner": self.planner,
            "service_point": [float(v) for v in self.service_point],
            "power_w": [float(v) for v in self.power_w],
            "power_levels": [int(v) for v in self.levels],
            # null for users given no power: they are not served
            "sinr_db": [float(v) if np.isfinite(v) else None for v in self.sinr_db],
            "rate_bps": [float(v) for v in self.rate_bps],
            "sum_rate_bps": float(self.sum_rate_bps),
            "qos_satisfied": int(self.qos_satisfied),
            "objective": float(self.objective),
            "naive_objective": float(self.naive_objective),
            "ergodic_sum_rate_bps": float(self.ergodic_sum_rate_bps),
            "ergodic_objective": float(self.ergodic_objective),
            "users": [[float(v) for v in u] for u in self.users],
            "search_points": len(self.visited),
            "service_wall_s": round(float(self.wall_s), 3),
            **self.extras,
        }


def run_service_stage(
    scenario: Scenario, planner: str | None = None, progress: Progress | None = None
) -> dict[str, Any]:
    """The summary fields of the service-point stage (what `uavxai service` prints)."""
    return plan_service(scenario, planner, progress).to_summary()


def plan_service(
    scenario: Scenario, planner: str | None = None, progress: Progress | None = None
) -> ServiceResult:
    """The service point and power allocation of ``planner`` (default the scenario's);
    ``progress(settled, total)`` hears how far the exact grid search is (the others are
    quick)."""
    t0 = time.perf_counter()
    name = planner or scenario.service.planner
    if name not in PLANNERS:
        raise UserError(f"service planner '{name}' is unknown; allowed: {', '.join(PLANNERS)}.")
    env = ServiceEnv.from_scenario(scenario)
    orbit = OrbitObjective.from_scenario(scenario, env.channel, env.power_levels)
    extras: dict[str, Any] = {
        "access": scenario.comms.access,
        "environment": scenario.comms.environment,
        "channel": scenario.comms.channel,
        "fading": scenario.comms.fading,
        "shadowing": scenario.comms.shadowing,
    }
    if name == "grid":
        if orbit is None:
            best = solve_grid(env.channel, env.space, env.power_levels, progress=progress)
        else:
            best = solve_grid_orbit(orbit, env.space, progress)
        levels, position = best.levels, best.position
        visited = np.array([env.space.start, position])
        extras.update(lattice_points=best.lattice_points, grid_evaluations=best.evaluations)
    elif name == "random":
        rng = np.random.default_rng(scenario.seed)
        ep = random_search(env, scenario.service.steps, rng, orbit.value if orbit else None)
        levels, position, visited = ep.levels, ep.position, ep.path
    else:
        ep, info = _learned_search(scenario, env, name, orbit)
        levels, position, visited = ep.levels, ep.position, ep.path
        extras.update(info)
    return _report(name, scenario, env, position, levels, visited, t0, extras)


def _learned_search(
    scenario: Scenario, env: ServiceEnv, algo: str, orbit: OrbitObjective | None = None
) -> tuple[d3qn.Episode, dict[str, Any]]:
    given = scenario.service.checkpoint
    if given is not None and not _is_universal(Path(given)):
        # A per-layout model from `uavxai train`: fly it as it is.
        net, info, _ = resolve_checkpoint(scenario, algo)
        return d3qn.rollout(net, d3qn.fading_free(env)), {"checkpoint": info["path"]}
    policy, label = universal_policy(scenario, algo)
    result = universal.plan(policy, d3qn.fading_free(env), scorer=orbit)
    flight, position, levels = result.flight, result.position, result.levels
    report = {
        "checkpoint": label,
        "d3qn_alone_objective": float(flight.objective),
        "d3qn_alone_point": [float(v) for v in flight.position],
        "flight_steps": len(flight.path) - 1,
        "refine_rounds": int(result.refine_rounds),
    }
    if orbit is not None:  # the network's own point and levels, judged on the orbit
        alone = orbit.value(flight.position, flight.levels)
        report["d3qn_alone_orbit_objective"] = float(alone[0])
    path = np.vstack([flight.path, position[None]])
    return d3qn.Episode(result.objective, position, levels, path), report


def _is_universal(path: Path) -> bool:
    try:
        data = torch.load(path, map_location="cpu", weights_only=True)
    except Exception:  # noqa: BLE001 - resolve_checkpoint reports unreadable files
        return False
    return isinstance(data, dict) and data.get("format") == checkpoint.FORMATS["universal"][0]


_POLICIES: dict[str, tuple[universal.NumpyPolicy, dict[str, Any]]] = {}


def check_planner_fits(scenario: Scenario, planner: str | None = None) -> None:
    """A UserError, before anything flies, when the learned service planner that would run
    (``planner`` or the scenario's) has no shipped model for the scenario's K and power
    levels (``uavxai validate`` and ``run`` ask this). Cheap: reads the JSON beside the
    shipped model, not the model."""
    name = planner or scenario.service.planner
    if name not in ("d3qn", "dqn") or scenario.service.checkpoint is not None:
        return
    c = scenario.comms
    meta = universal.shipped_path(name, c.power_levels).with_suffix(".json")
    if not meta.is_file():
        have = sorted(p.stem for p in service_checkpoints_dir().glob("universal_*.json"))
        raise UserError(
            f"service.planner {name} has no shipped model for comms.power_levels = "
            f"{c.power_levels} (shipped: {', '.join(have) or 'none'}); use power_levels 6, "
            "service.planner grid or random, or a model of your own (service.checkpoint). "
            "See docs/scenario.md."
        )
    lo, hi = json.loads(meta.read_text())["k_range"]
    if not lo <= c.users.k <= hi:
        raise UserError(
            f"comms.users: {c.users.k} users, but the shipped {name} model serves {lo} to "
            f"{hi}; use service.planner grid or random, or train one (python -m "
            f"uavxai.service.universal --algo {name}). See docs/scenario.md."
        )


def universal_model_path(scenario: Scenario, algo: str) -> Path:
    """``service.checkpoint``, or the shipped universal model for ``algo``."""
    given = scenario.service.checkpoint
    if given is not None:
        return Path(given)
    return universal.shipped_path(algo, scenario.comms.power_levels)


def universal_policy(scenario: Scenario, algo: str) -> tuple[universal.NumpyPolicy, str]:
    """The universal model for ``algo`` (``service.checkpoint`` or the shipped one), checked
    against the scenario's K and power levels; loaded once per process."""
    c = scenario.comms
    given = scenario.service.checkpoint
    path = universal_model_path(scenario, algo)
    if given is None and not path.is_file():
        have = sorted(p.name for p in service_checkpoints_dir().glob("universal_*.pt"))
        raise CheckpointError(
            f"no shipped {algo} model for power_levels = {c.power_levels}; shipped: "
            f"{', '.join(have) or 'none'}. Set comms.power_levels: 6, train one with "
            f"`uavxai train SCENARIO --stage universal --algo {algo}`, or use service.planner: "
            "grid or random."
        )
    key = str(path.resolve())
    if key not in _POLICIES:
        net, info = universal.load(path)
        _POLICIES[key] = (universal.NumpyPolicy(net), info)
    policy, info = _POLICIES[key]
    problems = []
    if info["algo"] != algo:
        problems.append(f"it is a {info['algo']} model but the planner is {algo}")
    if not 2 <= c.users.k <= info["k_max"]:
        problems.append(f"it serves K = 2..{info['k_max']} users, the scenario has {c.users.k}")
    if info["power_levels"] != c.power_levels:
        problems.append(
            f"it was trained for power_levels = {info['power_levels']}, the scenario has "
            f"{c.power_levels}"
        )
    if problems:
        raise CheckpointError(
            f"service model {path}: does not fit this scenario: {'; '.join(problems)}. Use "
            "service.planner: grid or random, or train a matching model with "
            f"`uavxai train SCENARIO --stage universal --algo {algo}`."
        )
    return policy, (str(path) if given is not None else f"shipped:{path.name}")


def shipped_checkpoint(k: int, power_levels: int, access: str) -> Path:
    return service_checkpoints_dir() / f"d3qn_k{k}_l{power_levels}_{access}.pt"


def resolve_checkpoint(
    scenario: Scenario, algo: str
) -> tuple[d3qn.BranchingQNetwork, dict[str, Any], bool]:
    """A per-layout model written by `uavxai train` (``service.checkpoint``)."""
    c = scenario.comms
    k, L = c.users.k, c.power_levels
    train_hint = f"`uavxai train SCENARIO --stage service --algo {algo}`"
    given = scenario.service.checkpoint
    if given is None:
        path = universal.shipped_path(algo, L)
        raise CheckpointError(f"no per-layout {algo} model given; the shipped one is {path}.")
    path = Path(given)
    net, info = d3qn.load_checkpoint(path)
    problems = []
    if info["algo"] != algo:
        problems.append(f"it is a {info['algo']} model but the planner is {algo}")
    if info["k"] != k:
        problems.append(f"it was trained for K = {info['k']} users, the scenario has {k}")
    if info["power_levels"] != L:
        problems.append(
            f"it was trained for power_levels = {info['power_levels']}, the scenario has {L}"
        )
    if problems:
        raise CheckpointError(
            f"service.checkpoint {path}: does not fit this scenario: {'; '.join(problems)}. "
            f"Train a matching model with {train_hint}."
        )
    info["path"] = str(path)
    return net, info, False


def _report(
    name: str,
    scenario: Scenario,
    env: ServiceEnv,
    position: np.ndarray,
    levels: np.ndarray,
    visited: np.ndarray,
    t0: float,
    extras: dict[str, Any],
) -> ServiceResult:
    channel: Channel = env.channel
    levels = np.asarray(levels, dtype=np.int64)
    power = levels_to_power(levels, channel.p_max_w, env.power_levels)
    link = channel.evaluate(position, power)
    rng = np.random.default_rng(scenario.seed)
    draws = np.broadcast_to(position, (ERGODIC_DRAWS, 3))
    ergodic = channel.evaluate(draws, power, rng)
    extras = {**extras, **orbit_fields(scenario, channel, position, power)}
    return ServiceResult(
        planner=name,
        users=channel.users,
        service_point=np.asarray(position, dtype=float),
        levels=levels,
        power_w=power,
        sinr_db=link.sinr_db,
        rate_bps=link.rate_bps,
        sum_rate_bps=float(link.sum_rate_bps),
        qos_satisfied=int((link.rate_bps >= channel.qos_rate_bps).sum()),
        objective=float(link.objective),
        visited=np.asarray(visited, dtype=float),
        naive_objective=env.naive_objective,
        ergodic_sum_rate_bps=float(ergodic.sum_rate_bps.mean()),
        ergodic_objective=float(ergodic.objective.mean()),
        wall_s=time.perf_counter() - t0,
        extras=extras,
    )


def orbit_fields(
    scenario: Scenario, channel: Channel, position: np.ndarray, power_w: np.ndarray
) -> dict[str, Any]:
    """What the orbit the mission flies about ``position`` gives with ``power_w``, fading-free
    (``platform`` says which objective chose the point)."""
    from uavxai.dynamics.orbit import scenario_orbit_radius

    radius = scenario_orbit_radius(scenario)
    avg = orbit_average(channel, np.asarray(position, dtype=float), radius, power_w)
    return {
        "platform": scenario.service.platform,
        "orbit_radius_m": float(radius),
        "orbit_objective": float(avg.objective),
        "orbit_sum_rate_bps": float(avg.sum_rate_bps),
        "orbit_qos_satisfied": int((avg.rate_bps >= channel.qos_rate_bps).sum()),
    }
