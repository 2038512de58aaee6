"""Placement benchmark of issue 13: the universal D3QN zero-shot against the exact optimum.

Unseen random problems (``uavxai.service.layouts``, seeds disjoint from training) for every
cell access {shared, ofdma} x environment {suburban, urban, dense_urban, highrise_urban} x
K {5, 10, 20} x users {uniform, clustered}, fading-free. Two steps:

    python benchmarks/studies/bench_placement.py optima --layouts 50 --minutes 40
        [--part 0 --parts 2]
    python benchmarks/studies/bench_placement.py evaluate --layouts N [--part 0 --parts 2]
    python benchmarks/studies/bench_placement.py report --layouts N
        [--plot docs/service/placement.png]

``optima`` solves the exact optimum (``grid``, seeded with the d3qn planner's answer) of each
problem and appends it to ``docs/service/bench_placement_optima.jsonl``, layout index by
layout index over every cell, so a run stopped by its time budget leaves every cell with the
same count (give or take one); resumable, and ``--part/--parts`` split it over processes.
``evaluate`` runs every method on the cached problems with ``i < N`` and appends to
``bench_placement_runs.jsonl`` (resumable, splittable the same way); ``report`` prints the
table over what both have:

- ``d3qn``: the shipped universal D3QN flown greedily (no per-layout training), its best
  visited point with its own power levels (``d3qn alone``), and what ``service.planner: d3qn``
  returns (the same flight plus the documented lattice/power refinement, ``d3qn+refine``);
- ``dqn``: the shipped DQN ablation, the same two numbers;
- ``refine_only``: the refinement alone from the flight's start (region centre, 100 m, all
  levels full), no network: what the network adds over the final polish;
- ``random``: random lattice points and levels for the same wall time as ``d3qn+refine``;
- ``grid``: the cached optimum and the time it took;

and prints, per cell, the ratio to the optimum (mean, 5th percentile), the share of the
naive-to-optimum gap closed ((x - naive) / (opt - naive), mean over layouts with a gap above
0.1 % of the optimum) and the time per layout.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np
import torch

from uavxai.comms.channel import ENVIRONMENTS
from uavxai.service import universal
from uavxai.service.grid import solve_grid
from uavxai.service.layouts import ACCESS, KINDS, draw_layout, problem_scenario
from uavxai.service.service_env import HOVER, ServiceEnv, levels_to_power

BENCH_SEED = 13_000  # training uses default_rng([seed < 1000, episode]): disjoint
KS = (5, 10, 20)
CACHE = Path(__file__).resolve().parents[2] / "docs" / "service" / "bench_placement_optima.jsonl"
RUNS = CACHE.with_name("bench_placement_runs.jsonl")  # every method on every cached problem
ABLATION = CACHE.with_name("bench_placement_ablation.jsonl")  # no_network for earlier runs
# Rows solved by the faster exact solver (a hint, block DP, failure cap) carry solver = 3; the
# optimum is the same, only the time differs, so the table times `grid` on those rows only.
SOLVER = 3


def cells() -> list[tuple[str, str, int, str]]:
    return list(itertools.product(ACCESS, ENVIRONMENTS, KS, KINDS))


def problem(access: str, environment: str, k: int, kind: str, i: int) -> np.ndarray:
    """The i-th unseen layout of a cell (users (K, 2)); the same for every run."""
    cell = cells().index((access, environment, k, kind))
    return draw_layout(np.random.default_rng([BENCH_SEED, cell, i]), k, kind)


def load_cache(path: Path = CACHE) -> list[dict]:
    if not path.is_file():
        return []
    rows, seen = [], set()
    for line in path.read_text().splitlines():
        if line.strip():
            row = json.loads(line)
            key = tuple(row[f] for f in (*CELL_FIELDS, "i"))
            if key not in seen:  # two `optima` processes may both solve a problem
                seen.add(key)
                rows.append(row)
    return rows


def optima(
    minutes: float, layouts: int, part: int = 0, parts: int = 1, path: Path = CACHE
) -> None:
    """Solve and cache the optima, layout index by layout index across every cell (so a run
    stopped by its time budget leaves every cell with the same count, give or take one);
    process ``part`` of ``parts`` takes the problems with ``(cell + i) % parts == part``.
    The exact solver is seeded with the d3qn planner's answer (``solve_grid(hint=...)``):
    only its pruning depends on that, never its result."""
    done = {tuple(r[f] for f in (*CELL_FIELDS, "i")) for r in load_cache(path)}
    net, _ = universal.load(universal.shipped_path("d3qn"))
    policy = universal.NumpyPolicy(net)
    deadline = time.monotonic() + 60.0 * minutes
    for i in range(layouts):
        for n, (access, environment, k, kind) in enumerate(cells()):
            if (n + i) % parts != part or (access, environment, k, kind, i) in done:
                continue
            if time.monotonic() > deadline:
                print("time budget reached", flush=True)
                return
            users = problem(access, environment, k, kind, i)
            env = ServiceEnv.from_scenario(problem_scenario(users, access, environment))
            hint = universal.plan(policy, env).position
            t0 = time.perf_counter()
            best = solve_grid(env.channel, env.space, env.power_levels, hint=hint)
            row = {
                "access": access,
                "environment": environment,
                "k": k,
                "kind": kind,
                "i": i,
                "users": users.round(3).tolist(),
                "optimum": best.objective,
                "position": best.position.tolist(),
                "levels": best.levels.tolist(),
                "naive": env.naive_objective,
                "grid_s": round(time.perf_counter() - t0, 2),
                "solver": SOLVER,
            }
            with path.open("a") as f:
                f.write(json.dumps(row) + "\n")
            print(access, environment, k, kind, i, f"{row['grid_s']} s", flush=True)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    sub = parser.add_subparsers(dest="command", required=True)
    o = sub.add_parser("optima")
    o.add_argument("--minutes", type=float, default=60.0)
    o.add_argument("--layouts", type=int, default=50, help="per cell")
    o.add_argument("--part", type=int, default=0, help="this process's share, 0..parts-1")
    o.add_argument("--parts", type=int, default=1, help="processes sharing the work")
    e = sub.add_parser("evaluate")
    e.add_argument("--models", type=Path, default=None, help="dir with universal_*_l6.pt")
    e.add_argument("--layouts", type=int, default=50, help="problems i < this per cell")
    e.add_argument("--part", type=int, default=0)
    e.add_argument("--parts", type=int, default=1)
    a = sub.add_parser("ablate", help="add the no_network ablation to earlier runs")
    a.add_argument("--layouts", type=int, default=50)
    a.add_argument("--part", type=int, default=0)
    a.add_argument("--parts", type=int, default=1)
    w = sub.add_parser("timing", help="wall time of the d3qn planner (run on a quiet machine)")
    w.add_argument("--layouts", type=int, default=5, help="per cell")
    r = sub.add_parser("report")
    r.add_argument("--plot", type=Path, default=None)
    r.add_argument("--json", type=Path, default=None)
    r.add_argument("--layouts", type=int, default=50, help="problems i < this per cell")
    c = sub.add_parser("curves", help="validation curves of the shipped models' training logs")
    c.add_argument("--plot", type=Path, required=True)
    args = parser.parse_args(argv)
    torch.set_num_threads(1)
    if args.command == "curves":
        plot_curves(args.plot)
        return
    if args.command == "optima":
        optima(args.minutes, args.layouts, args.part, args.parts)
    elif args.command == "evaluate":
        evaluate(args.models, args.layouts, args.part, args.parts)
    elif args.command == "timing":
        timing(args.layouts)
    elif args.command == "ablate":
        ablate(args.layouts, args.part, args.parts)
    else:
        report(args.plot, args.json, args.layouts)


METHODS = (
    "d3qn", "d3qn_alone", "dqn", "dqn_alone", "no_network", "refine_only", "random", "naive"
)  # fmt: skip


class NoNetwork(universal.NumpyPolicy):
    """The network's ablation inside the planner: a "flight" that hovers at the region centre
    with equal power, so that ``universal.plan`` runs every search step (refinement from there,
    screened starts, kicks, exact power and climb) without anything learned: what the planner
    owes the network is the difference to ``d3qn``."""

    def __init__(self, power_levels: int) -> None:  # no weights to hold
        self.top = power_levels - 1

    def __call__(self, obs: universal.Observation) -> np.ndarray:
        return np.concatenate([[HOVER], np.full(len(obs.users), self.top)])


# Times per layout are this process's CPU time (one thread: torch and BLAS are held to one),
# so that the load of other jobs on the shared machine does not enter; the wall time of the
# d3qn planner is kept beside it (``d3qn_wall_s``).
cpu = time.process_time


def random_for(env: ServiceEnv, seconds: float, rng: np.random.Generator) -> float:
    """The best of random lattice points with random levels drawn for ``seconds`` of CPU."""
    axes = env.space.axes()
    best, t0 = -np.inf, cpu()
    while True:
        pos = np.column_stack([rng.choice(axis, size=32) for axis in axes])
        levels = rng.integers(0, env.power_levels, size=(32, env.channel.k))
        power = levels_to_power(levels, env.channel.p_max_w, env.power_levels)
        best = max(best, float(env.channel.evaluate(pos, power).objective.max()))
        if cpu() - t0 >= seconds:
            return best


def run_problem(row: dict, policies: dict[str, universal.NumpyPolicy]) -> dict[str, float]:
    users = np.asarray(row["users"])
    env = ServiceEnv.from_scenario(problem_scenario(users, row["access"], row["environment"]))
    out = {"optimum": row["optimum"], "naive": env.naive_objective, "grid_s": row["grid_s"],
           "solver": row.get("solver", 1)}
    out["naive_obj"] = env.naive_objective
    for algo, policy in policies.items():
        t0 = cpu()
        flight = universal.fly(policy, env)
        t1, wall = cpu(), time.perf_counter()
        value = universal.plan(policy, env).objective  # flies again: time the whole planner
        out[f"{algo}_wall_s"] = time.perf_counter() - wall
        out[f"{algo}_alone"], out[f"{algo}_alone_s"] = flight.objective, t1 - t0
        out[algo], out[f"{algo}_s"] = value, cpu() - t1
    out.update(no_network(env))
    # What the refinement finds without any network: from the flight's start, all levels full.
    t0 = cpu()
    full = np.full(env.channel.k, env.power_levels - 1)
    _, _, out["refine_only"], _ = universal.refine(
        env.channel, env.space, env.power_levels, env.space.start, full
    )
    out["refine_only_s"] = cpu() - t0
    rng = np.random.default_rng([row["k"], row["i"]])
    out["random_s"] = out["d3qn_s"]
    out["random"] = random_for(env, out["d3qn_s"], rng)
    return out


def no_network(env: ServiceEnv) -> dict[str, float]:
    t0 = cpu()
    value = universal.plan(NoNetwork(env.power_levels), env).objective
    return {"no_network": value, "no_network_s": cpu() - t0}


def ablate(layouts: int, part: int = 0, parts: int = 1) -> None:
    """Add the ``no_network`` ablation to runs made before it existed: one line per problem
    in ``ABLATION`` (resumable), merged into the runs by ``load_runs``."""
    done = set()
    if ABLATION.is_file():
        done = {tuple(json.loads(x)[f] for f in (*CELL_FIELDS, "i"))
                for x in ABLATION.read_text().splitlines() if x.strip()}  # fmt: skip
    rows = [r for r in load_cache() if r["i"] < layouts]
    for n, row in enumerate(rows):
        key = tuple(row[f] for f in (*CELL_FIELDS, "i"))
        if n % parts != part or key in done:
            continue
        env = ServiceEnv.from_scenario(
            problem_scenario(np.asarray(row["users"]), row["access"], row["environment"])
        )
        out = {**dict(zip((*CELL_FIELDS, "i"), key, strict=True)), **no_network(env)}
        with ABLATION.open("a") as f:
            f.write(json.dumps(out) + "\n")
        if (n + 1) % 100 == 0:
            print(f"{n + 1}/{len(rows)} problems", flush=True)


def timing(layouts: int) -> None:
    """Wall time of the d3qn planner per layout, the first ``layouts`` of every cell (no exact
    optimum needed): run it on a quiet machine; ``evaluate`` reports CPU time."""
    net, _ = universal.load(universal.shipped_path("d3qn"))
    policy = universal.NumpyPolicy(net)
    walls = []
    for access, environment, k, kind in cells():
        for i in range(layouts):
            users = problem(access, environment, k, kind, i)
            env = ServiceEnv.from_scenario(problem_scenario(users, access, environment))
            t0 = time.perf_counter()
            universal.plan(policy, env)
            walls.append(1e3 * (time.perf_counter() - t0))
    w = np.array(walls)
    print(f"d3qn planner wall time over {len(w)} layouts ({layouts} per cell): mean "
          f"{w.mean():.1f} ms, 95th pct {np.percentile(w, 95):.1f} ms, max {w.max():.1f} ms")


def summarise(rows: list[dict], results: list[dict]) -> dict[tuple, dict[str, float]]:
    table: dict[tuple, dict[str, float]] = {}
    for key in cells():
        idx = [n for n, r in enumerate(rows) if tuple(r[f] for f in CELL_FIELDS) == key]
        if not idx:
            continue
        res = [results[n] for n in idx]
        opt = np.array([r["optimum"] for r in res])
        naive = np.array([r["naive_obj"] for r in res])
        gap = opt - naive
        has_gap = gap > 1e-3 * opt
        timed = [r["grid_s"] for r in res if r["solver"] == SOLVER]  # this solver's rows only
        cell = {"n": len(res), "grid_s": float(np.mean(timed)) if timed else float("nan")}
        for m in METHODS:
            x = np.array([r["naive_obj"] if m == "naive" else r[m] for r in res])
            ratio = x / opt
            cell[f"{m}_mean"] = float(ratio.mean())
            cell[f"{m}_p5"] = float(np.percentile(ratio, 5))
            cell[f"{m}_gap"] = (
                float(np.mean((x[has_gap] - naive[has_gap]) / gap[has_gap]))
                if has_gap.any()
                else float("nan")
            )
            if m != "naive":
                cell[f"{m}_ms"] = 1e3 * float(np.mean([r[f"{m}_s"] for r in res]))
        table[key] = cell
    return table


CELL_FIELDS = ("access", "environment", "k", "kind")


def evaluate(models: Path | None, layouts: int, part: int = 0, parts: int = 1) -> None:
    """Run every method on the cached problems with ``i < layouts`` (this process's share) and
    append one line per problem to ``RUNS`` (resumable; ``report`` reads it)."""
    policies = {}
    for algo in ("d3qn", "dqn"):
        path = models / f"universal_{algo}_l6.pt" if models else universal.shipped_path(algo)
        net, _ = universal.load(path)
        policies[algo] = universal.NumpyPolicy(net)
    done = {key for key, _ in load_runs()}
    rows = [r for r in load_cache() if r["i"] < layouts]
    for n, row in enumerate(rows):
        key = tuple(row[f] for f in (*CELL_FIELDS, "i"))
        if n % parts != part or key in done:
            continue
        out = {**dict(zip((*CELL_FIELDS, "i"), key, strict=True)), **run_problem(row, policies)}
        with RUNS.open("a") as f:
            f.write(json.dumps(out) + "\n")
        if (n + 1) % 25 == 0:
            print(f"{n + 1}/{len(rows)} problems", flush=True)


def load_runs() -> list[tuple[tuple, dict]]:
    if not RUNS.is_file():
        return []
    runs = [json.loads(line) for line in RUNS.read_text().splitlines() if line.strip()]
    extra = {}
    if ABLATION.is_file():
        for line in ABLATION.read_text().splitlines():
            if line.strip():
                r = json.loads(line)
                extra[tuple(r[f] for f in (*CELL_FIELDS, "i"))] = r
    keyed = [(tuple(r[f] for f in (*CELL_FIELDS, "i")), r) for r in runs]
    return [(key, {**extra.get(key, {}), **r}) for key, r in keyed]


def report(plot: Path | None, out_json: Path | None, layouts: int) -> None:
    """The table over the problems with ``i < layouts`` that ``evaluate`` has run."""
    runs = dict(load_runs())
    rows = [r for r in load_cache() if r["i"] < layouts]
    rows = [r for r in rows if tuple(r[f] for f in (*CELL_FIELDS, "i")) in runs]
    results = [runs[tuple(r[f] for f in (*CELL_FIELDS, "i"))] for r in rows]
    table = summarise(rows, results)
    head = (
        "| access | environment | K | users | n | d3qn mean / p5 / gap | d3qn alone mean / p5 "
        "| dqn mean / p5 / gap | dqn alone mean / p5 | random (equal time) mean / p5 | naive "
        "mean | d3qn ms | grid s |"
    )
    print(head)
    print("|" + "---|" * 13)
    for key, c in table.items():
        print(
            f"| {' | '.join(str(v) for v in key)} | {c['n']} "
            f"| {c['d3qn_mean']:.4f} / {c['d3qn_p5']:.4f} / {100 * c['d3qn_gap']:.0f} % "
            f"| {c['d3qn_alone_mean']:.4f} / {c['d3qn_alone_p5']:.4f} "
            f"| {c['dqn_mean']:.4f} / {c['dqn_p5']:.4f} / {100 * c['dqn_gap']:.0f} % "
            f"| {c['dqn_alone_mean']:.4f} / {c['dqn_alone_p5']:.4f} "
            f"| {c['random_mean']:.4f} / {c['random_p5']:.4f} | {c['naive_mean']:.4f} "
            f"| {c['d3qn_ms']:.0f} | {c['grid_s']:.1f} |"
        )
    print()
    for m in METHODS:
        means = [c[f"{m}_mean"] for c in table.values()]
        p5s = [c[f"{m}_p5"] for c in table.values()]
        gaps = [c[f"{m}_gap"] for k, c in table.items() if k[0] == "ofdma"]
        ms = [c.get(f"{m}_ms", np.nan) for c in table.values()]
        if m == "naive":
            ms = [0.0]
        met = sum(mu >= 0.99 and p5 >= 0.97 for mu, p5 in zip(means, p5s, strict=True))
        print(
            f"{m:11s} mean of cell means {np.mean(means):.4f}, worst cell mean {min(means):.4f},"
            f" worst cell p5 {min(p5s):.4f}, ofdma gap closed mean {100 * np.nanmean(gaps):.0f} %"
            f" worst {100 * np.nanmin(gaps):.0f} %, ms/layout mean {np.nanmean(ms):.0f} "
            f"max cell {np.nanmax(ms):.0f}; goal met in {met} of {len(table)} cells"
        )
    worst = sorted(table.items(), key=lambda kc: min(kc[1]["d3qn_mean"] - 0.99,
                                                     kc[1]["d3qn_p5"] - 0.97))[:4]
    print("worst cells for d3qn (mean / p5): " + "; ".join(
        f"{' '.join(str(v) for v in k)} (n = {c['n']}): {c['d3qn_mean']:.4f} / {c['d3qn_p5']:.4f}"
        for k, c in worst))
    counts = [c["n"] for c in table.values()]
    for name, field in (("CPU", "d3qn_s"), ("wall (under load)", "d3qn_wall_s")):
        every = np.array([1e3 * r[field] for r in results])
        print(
            f"d3qn planner per layout, {name}: mean {every.mean():.0f} ms, 95th pct "
            f"{np.percentile(every, 95):.0f} ms, max {every.max():.0f} ms, over {len(results)} "
            f"problems, {min(counts)}-{max(counts)} per cell"
        )
    if out_json is not None:
        out_json.write_text(
            json.dumps([{**dict(zip(CELL_FIELDS, k, strict=True)), **c} for k, c in table.items()],
                       indent=1)
        )
    if plot is not None:
        _plot(plot, table)


def plot_curves(path: Path) -> None:
    """Greedy validation score (mean log2 of objective / reference over 24 fixed problems)
    every 100 episodes, from ``docs/service/universal_{algo}_train_log.jsonl``."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(7, 4), constrained_layout=True)
    for algo, colour in (("d3qn", "tab:red"), ("dqn", "tab:blue")):
        log = CACHE.parent / f"universal_{algo}_train_log.jsonl"
        rows = [json.loads(line) for line in log.read_text().splitlines() if line.strip()]
        ax.plot([r["episode"] for r in rows], [r["val_log2_over_reference"] for r in rows],
                "o-", color=colour, label=algo.upper())
    ax.set(xlabel="training episode (a new random problem each)",
           ylabel="validation: mean log2(greedy best / reference)",
           title="Universal D3QN / DQN: greedy flight alone on 24 fixed problems")
    ax.grid(alpha=0.3)
    ax.legend()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def _plot(path: Path, table: dict[tuple, dict[str, float]]) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    style = {
        "d3qn": ("tab:red", "o", "d3qn (planner: flight + refine)"),
        "d3qn_alone": ("tab:orange", "^", "D3QN alone (best visited point)"),
        "dqn_alone": ("tab:blue", "v", "DQN alone"),
        "random": ("tab:gray", "s", "random, equal time"),
        "refine_only": ("tab:purple", "d", "refine alone from the start (no network)"),
        "naive": ("tab:green", "x", "naive (centroid, 100 m, equal power)"),
    }
    fig, axes = plt.subplots(2, 1, figsize=(14, 8), constrained_layout=True)
    for ax, access in zip(axes, ACCESS, strict=True):
        keys = [k for k in table if k[0] == access]
        x = np.arange(len(keys))
        for j, (m, (colour, marker, label)) in enumerate(style.items()):
            mean = np.array([table[k][f"{m}_mean"] for k in keys])
            p5 = np.array([table[k][f"{m}_p5"] for k in keys])
            off = (j - 2.5) * 0.1
            # max(): the mean can sit a rounding error below the 5th percentile of equal values
            ax.errorbar(x + off, mean, yerr=[np.maximum(mean - p5, 0), 0 * mean], fmt=marker,
                        color=colour, label=label, ms=5, capsize=2)
        ax.axhline(0.99, color="k", ls="--", lw=0.8)
        ax.axhline(0.97, color="k", ls=":", lw=0.8)
        ax.set_xticks(x, [f"{k[1][:8]} K{k[2]} {k[3][:4]}" for k in keys], rotation=70, fontsize=7)
        ax.set_ylabel("objective / exact optimum")
        ax.set_ylim(max(0.0, ax.get_ylim()[0]), 1.01)
        ax.set_title(f"{access}: mean (marker) and 5th percentile (whisker) per cell")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=8, loc="lower left")
    fig.savefig(path, dpi=100)
    plt.close(fig)


if __name__ == "__main__":
    main()
