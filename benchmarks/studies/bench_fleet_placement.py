"""Fleet placement benchmark of issue 32 (Must-show 1): the fleet planner against the
reference and the k-means baseline, fading-free.

Cells N in {2, 3, 4} x K in {10, 20, 40} x access {shared, ofdma} x channel {al_hourani,
uma_av} (urban), ``--layouts`` unseen layouts per cell (even indices uniform, odd clustered,
``uavxai.service.layouts.draw_layout`` from ``default_rng([BENCH_SEED, cell, i])``; no seed of
these was used to tune anything). Per cell: planner / reference (mean, p5), planner / k-means
(mean), the planner's wall time (p50, max, ms) and the reference's (mean, s); then the worst
cell; in OFDMA also the certified upper bound (``upper_bound``): ``ref/ub`` the worst
reference / bound of the cell (the best known fleet is at least that fraction of the
optimum) and ``ub/km`` the mean bound / k-means (no fleet gains more over the baseline). Rows
are appended to ``--out`` (JSON lines) as they finish, so a run cut short by
``timeout`` keeps what it did; a run with the same ``--out`` skips the (cell, layout) pairs
already there, so the full table can be run over several sessions, and ``--shard i/n`` takes
every n-th of the remaining (cell, layout) jobs, so n processes can share it.

    python benchmarks/studies/bench_fleet_placement.py --quick            # 2 layouts per cell
    python benchmarks/studies/bench_fleet_placement.py --layouts 50 [--n 4 --k 40]
        [--out rows.jsonl]
    python benchmarks/studies/bench_fleet_placement.py --cells 0-11 --shard 0/2 --out rows.jsonl
    python benchmarks/studies/bench_fleet_placement.py --planner-only --n 4 --k 40 --layouts 10

Goals: planner >= 0.99 of the reference on the mean and >= 0.97 at p5, >= 1.15 x k-means on
the mean, planning <= 100 ms for N = 4, K = 40. Times are CPU time of this process
(``time.process_time``), less sensitive to whatever else runs on the machine than wall time,
though a loaded machine still slows them (shared caches).
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np

from uavxai.service.fleet import (
    fleet_problem,
    kmeans_baseline,
    plan_fleet,
    reference_fleet,
    upper_bound,
)
from uavxai.service.layouts import draw_layout

BENCH_SEED = 32_000  # tests draw from small seeds; nothing was tuned on these
NS, KS = (2, 3, 4), (10, 20, 40)
ACCESS, MODELS = ("shared", "ofdma"), ("al_hourani", "uma_av")


def cells(ns, ks) -> list[tuple[int, int, str, str]]:
    return [c for c in itertools.product(NS, KS, ACCESS, MODELS) if c[0] in ns and c[1] in ks]


ALL_CELLS = list(itertools.product(NS, KS, ACCESS, MODELS))  # a cell's index is its seed


def run_one(cell: tuple[int, int, str, str], i: int, reference: bool = True) -> dict:
    """One layout of one cell: the planner, the k-means baseline and (unless not
    ``reference``) the reference, with their CPU times."""
    n, k, access, model = cell
    xy = draw_layout(np.random.default_rng([BENCH_SEED, ALL_CELLS.index(cell), i]), k,
                     "uniform" if i % 2 == 0 else "clustered")
    problem = fleet_problem(xy, n, access, model)
    t0 = time.process_time()
    plan = plan_fleet(problem)
    plan_s = time.process_time() - t0
    base = kmeans_baseline(problem)
    row = {"n": n, "k": k, "access": access, "model": model, "layout": i,
           "planner": plan.objective, "kmeans": base.objective, "planner_ms": 1e3 * plan_s,
           "cpu": "process_time"}
    if reference:
        t0 = time.process_time()
        row["reference"] = reference_fleet(problem, hint=plan).objective
        row["reference_s"] = time.process_time() - t0
        bound = upper_bound(problem)  # OFDMA only (inf: none built)
        if np.isfinite(bound):
            row["bound"] = bound
    return row


def summarise(rows: list[dict]) -> dict:
    """A cell's (or all rows') numbers; the reference's only over rows that have it."""
    ms = np.array([r["planner_ms"] for r in rows])
    gain = np.array([r["planner"] / r["kmeans"] for r in rows])
    out = {"layouts": len(rows), "vs_kmeans": gain.mean(), "vs_kmeans_median": np.median(gain),
           "ms_p50": np.median(ms), "ms_max": ms.max(), "mean": np.nan, "p5": np.nan,
           "ref_vs_kmeans": np.nan, "ref_s": np.nan, "ref_vs_bound": np.nan,
           "bound_vs_kmeans": np.nan}
    ref = [r for r in rows if "reference" in r]
    if ref:
        ratio = np.array([r["planner"] / r["reference"] for r in ref])
        out.update(mean=ratio.mean(), p5=np.percentile(ratio, 5),
                   ref_vs_kmeans=np.mean([r["reference"] / r["kmeans"] for r in ref]),
                   ref_s=np.mean([r["reference_s"] for r in ref]))
    bounded = [r for r in ref if "bound" in r]
    if bounded:  # how far the best known fleet can be from the optimum; the most over k-means
        out.update(ref_vs_bound=np.min([r["reference"] / r["bound"] for r in bounded]),
                   bound_vs_kmeans=np.mean([r["bound"] / r["kmeans"] for r in bounded]))
    return out


def report(rows: list[dict]) -> None:
    print(f"{'N':>2} {'K':>3} {'access':6} {'channel':10} {'n':>3} {'p/ref':>7} {'p5':>7} "
          f"{'p/kmeans':>9} {'(median)':>9} {'ref/km':>7} {'ms p50':>7} {'ms max':>7} "
          f"{'ref s':>6} {'ref/ub':>7} {'ub/km':>6}")
    table = []
    for cell in ALL_CELLS:
        mine = [r for r in rows if (r["n"], r["k"], r["access"], r["model"]) == cell]
        if not mine:
            continue
        s = summarise(mine)
        table.append((cell, s))
        print(f"{cell[0]:>2} {cell[1]:>3} {cell[2]:6} {cell[3]:10} {s['layouts']:>3} "
              f"{s['mean']:7.4f} {s['p5']:7.4f} {s['vs_kmeans']:9.3g} "
              f"{s['vs_kmeans_median']:9.3g} {s['ref_vs_kmeans']:7.3g} {s['ms_p50']:7.0f} "
              f"{s['ms_max']:7.0f} {s['ref_s']:6.1f} {s['ref_vs_bound']:7.4f} "
              f"{s['bound_vs_kmeans']:6.3f}")
    if not table:
        return
    whole = summarise(rows)
    print(f"all {whole['layouts']} layouts: planner/reference mean {whole['mean']:.4f}, p5 "
          f"{whole['p5']:.4f}; planner/k-means mean {whole['vs_kmeans']:.3g} "
          f"(median {whole['vs_kmeans_median']:.3g})")
    for what in ("mean", "p5", "vs_kmeans", "ref_vs_kmeans"):
        cell, s = min(table, key=lambda t: np.inf if np.isnan(t[1][what]) else t[1][what])
        print(f"worst cell by {what}: N={cell[0]} K={cell[1]} {cell[2]} {cell[3]}: "
              f"{s[what]:.4g} (mean {s['mean']:.4f}, p5 {s['p5']:.4f})")
    for access in ACCESS:
        big = [r["planner_ms"] for r in rows if (r["n"], r["k"], r["access"]) == (4, 40, access)]
        if big:
            print(f"planning N=4 K=40 {access}: p50 {np.median(big):.0f} ms, "
                  f"max {np.max(big):.0f} ms CPU")


def cell_indices(text: str) -> list[int]:
    """``--cells``: indices into the 36 cells (``ALL_CELLS`` order), e.g. ``0-11,30``."""
    out: list[int] = []
    for part in text.split(","):
        lo, _, hi = part.partition("-")
        try:
            out.extend(range(int(lo), int(hi or lo) + 1))
        except ValueError:
            raise SystemExit(f"--cells {text!r}: comma-separated indices or ranges in "
                             f"0-{len(ALL_CELLS) - 1}, e.g. 0-11,30") from None
    if not all(0 <= i < len(ALL_CELLS) for i in out):
        raise SystemExit(f"--cells {text!r}: indices run 0-{len(ALL_CELLS) - 1}")
    return out


def jobs(args: argparse.Namespace, done: set[tuple]) -> list[tuple[tuple, int]]:
    """The (cell, layout) pairs to run: layout by layout over every chosen cell (a cut run
    stays balanced), minus those ``done``, every n-th of them for shard i/n."""
    chosen = (cell_indices(args.cells) if args.cells else
              [j for j, c in enumerate(ALL_CELLS) if c[0] in args.n and c[1] in args.k])
    layouts = 2 if args.quick else args.layouts
    todo = [(ALL_CELLS[j], i) for i in range(layouts) for j in chosen
            if (*ALL_CELLS[j], i) not in done]
    shard, _, count = args.shard.partition("/")
    if not (shard.isdigit() and count.isdigit() and int(shard) < int(count)):
        raise SystemExit(f"--shard {args.shard!r}: i/n with 0 <= i < n, e.g. 0/2")
    return todo[int(shard) :: int(count)]


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", type=int, default=50)
    ap.add_argument("--quick", action="store_true", help="2 layouts per cell")
    ap.add_argument("--n", type=int, nargs="*", default=list(NS))
    ap.add_argument("--k", type=int, nargs="*", default=list(KS))
    ap.add_argument("--cells", default=None, help="cell indices 0-35 instead of --n/--k")
    ap.add_argument("--shard", default="0/1", help="i/n: every n-th job from the i-th")
    ap.add_argument("--planner-only", action="store_true", help="no reference (timing runs)")
    ap.add_argument("--out", type=Path, default=None, help="append rows here (JSON lines)")
    ap.add_argument("--report", type=Path, default=None, help="only print the table of a file")
    args = ap.parse_args(argv)
    if args.report is not None:
        report([json.loads(line) for line in args.report.read_text().splitlines() if line])
        return
    old = ([json.loads(line) for line in args.out.read_text().splitlines() if line]
           if args.out is not None and args.out.exists() else [])
    done = {(r["n"], r["k"], r["access"], r["model"], r["layout"]) for r in old
            if args.planner_only or "reference" in r}
    rows = []
    for cell, i in jobs(args, done):
        row = run_one(cell, i, reference=not args.planner_only)
        rows.append(row)
        if args.out is not None:
            with args.out.open("a") as f:
                f.write(json.dumps(row) + "\n")
    report(rows)


if __name__ == "__main__":
    main()
