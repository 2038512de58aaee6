"""Fleet placement benchmark of issue 32 (Must-show 1): the fleet planner against the
reference and the k-means baseline, fading-free.

Cells N in {2, 3, 4} x K in {10, 20, 40} x access {shared, ofdma} x channel {al_hourani,
uma_av} (urban), ``--layouts`` unseen layouts per cell (even indices uniform, odd clustered,
``uavxai.service.layouts.draw_layout`` from ``default_rng([BENCH_SEED, cell, i])``; no seed of
these was used to tune anything). Per cell: planner / reference (mean, p5), planner / k-means
(mean), the planner's wall time (p50, max, ms) and the reference's (mean, s); then the worst
cell. Rows are appended to ``--out`` (JSON lines) as they finish, so a run cut short by
``timeout`` keeps what it did.

    python benchmarks/bench_fleet_placement.py --quick            # 2 layouts per cell
    python benchmarks/bench_fleet_placement.py --layouts 50 [--n 4 --k 40] [--out rows.jsonl]

Goals: planner >= 0.99 of the reference on the mean and >= 0.97 at p5, >= 1.15 x k-means on
the mean, planning <= 100 ms for N = 4, K = 40. Wall times are those of the machine it runs
on, with whatever else runs there.
"""

from __future__ import annotations

import argparse
import itertools
import json
import time
from pathlib import Path

import numpy as np

from uavxai.service.fleet import fleet_problem, kmeans_baseline, plan_fleet, reference_fleet
from uavxai.service.layouts import draw_layout

BENCH_SEED = 32_000  # tests draw from small seeds; nothing was tuned on these
NS, KS = (2, 3, 4), (10, 20, 40)
ACCESS, MODELS = ("shared", "ofdma"), ("al_hourani", "uma_av")


def cells(ns, ks) -> list[tuple[int, int, str, str]]:
    return [c for c in itertools.product(NS, KS, ACCESS, MODELS) if c[0] in ns and c[1] in ks]


def run_one(cell_index: int, cell: tuple[int, int, str, str], i: int) -> dict:
    n, k, access, model = cell
    xy = draw_layout(np.random.default_rng([BENCH_SEED, cell_index, i]), k,
                     "uniform" if i % 2 == 0 else "clustered")
    problem = fleet_problem(xy, n, access, model)
    t0 = time.perf_counter()
    plan = plan_fleet(problem)
    plan_s = time.perf_counter() - t0
    base = kmeans_baseline(problem)
    t0 = time.perf_counter()
    ref = reference_fleet(problem, hint=plan)
    ref_s = time.perf_counter() - t0
    return {"n": n, "k": k, "access": access, "model": model, "layout": i,
            "planner": plan.objective, "reference": ref.objective, "kmeans": base.objective,
            "planner_ms": 1e3 * plan_s, "reference_s": ref_s}


def summarise(rows: list[dict]) -> dict:
    ratio = np.array([r["planner"] / r["reference"] for r in rows])
    gain = np.array([r["planner"] / r["kmeans"] for r in rows])
    ms = np.array([r["planner_ms"] for r in rows])
    return {"layouts": len(rows), "mean": ratio.mean(), "p5": np.percentile(ratio, 5),
            "vs_kmeans": gain.mean(), "vs_kmeans_median": np.median(gain),
            "ms_p50": np.median(ms), "ms_max": ms.max(),
            "ref_s": np.mean([r["reference_s"] for r in rows])}


def report(rows: list[dict]) -> None:
    print(f"{'N':>2} {'K':>3} {'access':6} {'channel':10} {'n':>3} {'p/ref':>7} {'p5':>7} "
          f"{'p/kmeans':>9} {'(median)':>9} {'ms p50':>7} {'ms max':>7} {'ref s':>6}")
    table = []
    for cell in itertools.product(NS, KS, ACCESS, MODELS):
        mine = [r for r in rows if (r["n"], r["k"], r["access"], r["model"]) == cell]
        if not mine:
            continue
        s = summarise(mine)
        table.append((cell, s))
        print(f"{cell[0]:>2} {cell[1]:>3} {cell[2]:6} {cell[3]:10} {s['layouts']:>3} "
              f"{s['mean']:7.4f} {s['p5']:7.4f} {s['vs_kmeans']:9.3g} "
              f"{s['vs_kmeans_median']:9.3g} {s['ms_p50']:7.0f} {s['ms_max']:7.0f} "
              f"{s['ref_s']:6.1f}")
    if not table:
        return
    whole = summarise(rows)
    print(f"all {whole['layouts']} layouts: planner/reference mean {whole['mean']:.4f}, p5 "
          f"{whole['p5']:.4f}; planner/k-means mean {whole['vs_kmeans']:.3g} "
          f"(median {whole['vs_kmeans_median']:.3g})")
    for what in ("mean", "p5", "vs_kmeans"):
        cell, s = min(table, key=lambda t: t[1][what])
        print(f"worst cell by {what}: N={cell[0]} K={cell[1]} {cell[2]} {cell[3]}: "
              f"{s[what]:.4g} (mean {s['mean']:.4f}, p5 {s['p5']:.4f})")
    big = [r["planner_ms"] for r in rows if r["n"] == 4 and r["k"] == 40]
    if big:
        print(f"planning N=4 K=40: p50 {np.median(big):.0f} ms, max {np.max(big):.0f} ms")


def main(argv: list[str] | None = None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--layouts", type=int, default=50)
    ap.add_argument("--quick", action="store_true", help="2 layouts per cell")
    ap.add_argument("--n", type=int, nargs="*", default=list(NS))
    ap.add_argument("--k", type=int, nargs="*", default=list(KS))
    ap.add_argument("--out", type=Path, default=None, help="append rows here (JSON lines)")
    ap.add_argument("--report", type=Path, default=None, help="only print the table of a file")
    args = ap.parse_args(argv)
    if args.report is not None:
        report([json.loads(line) for line in args.report.read_text().splitlines() if line])
        return
    layouts = 2 if args.quick else args.layouts
    todo = cells(args.n, args.k)
    index = {c: j for j, c in enumerate(itertools.product(NS, KS, ACCESS, MODELS))}
    rows = []
    for i in range(layouts):  # layout by layout over every cell: a cut run stays balanced
        for cell in todo:
            row = run_one(index[cell], cell, i)
            rows.append(row)
            if args.out is not None:
                with args.out.open("a") as f:
                    f.write(json.dumps(row) + "\n")
    report(rows)


if __name__ == "__main__":
    main()
