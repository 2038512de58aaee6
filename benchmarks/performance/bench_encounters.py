"""Encounter-campaign throughput (issue 27): what a 10^4-encounter campaign costs.

For each method, kinematic encounters of `scenarios/encounters.yaml` flown in this process:
CPU seconds per encounter and encounters per core-hour. Then one small campaign (the first
method) on 1 and 2 local workers and on a private Ray (`--ray`), wall time and speed-up
against 1 worker, measured in the same process. From these, the hours a campaign of
`--target` encounters per method takes on this machine.

    .venv/bin/python benchmarks/performance/bench_encounters.py [--encounters 8]
        [--methods none,mcts_daa] [--dynamics kinematic,jsbsim] [--target 10000] [--ray]
        [--no-scaling]

``--dynamics`` takes one or both (each measured in turn, in this process, after the other's
warm-up); ``--no-scaling`` measures the encounters only (the campaigns of the second part fly
2 x ``--encounters`` more of the first method and dynamics).

Measured (issues 27 and 31, before / after the throughput work: fly_end, the batch memo,
geometry.clip, the sampler's column; the same numbers to the bit), kinematic, seeds 1-10,
the two trees interleaved at load 8-11 on 2 CPUs: CPU s per encounter `none` 0.728 / 0.480,
`mcts_daa` 1.189 / 0.868, `mvp` 1.303 / 0.975; JSBSim (4 encounters) `none` 1.179 / 1.250,
`mcts_daa` 2.244 / 2.316 (unchanged within the noise: JSBSim's integration dominates).
On the idle machine (commit bcde9ec, `--encounters 150 --methods none --ray`): `none`
0.317 CPU s per encounter; 300 encounters 99.2 s on 1 worker, 48.9 s on 2 (speed-up 2.03),
58.3 s on a private Ray of 2 CPUs (1.70, its start inside); docs/cluster.md.

Prints numbers only; nothing is asserted. On a machine shared with other work the CPU times
hold better than the wall times: the load is printed beside them.
"""

from __future__ import annotations

import argparse
import os
import time

import torch

from uavxai.campaign import run_campaign, run_campaign_episode
from uavxai.paths import scenarios_dir
from uavxai.scenario import Scenario, load_scenario


def per_encounter(scenario, method: str, seeds: range, dynamics: str) -> tuple[float, float]:
    """CPU and wall seconds per encounter of ``method`` in this process (after a warm-up)."""
    run_campaign_episode(scenario, method, 1, seeds.start, dynamics)  # load, warm up
    c0, w0 = time.process_time(), time.perf_counter()
    for s in seeds:
        run_campaign_episode(scenario, method, 1, s, dynamics)
    return ((time.process_time() - c0) / len(seeds), (time.perf_counter() - w0) / len(seeds))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--encounters", type=int, default=8)
    ap.add_argument("--methods", default="none,mcts_daa,mcts_vertical,mvp")
    ap.add_argument("--dynamics", default="kinematic", help="kinematic, jsbsim or both, comma")
    ap.add_argument("--target", type=int, default=10_000)
    ap.add_argument("--ray", action="store_true", help="also a private Ray of 2 CPUs")
    ap.add_argument("--no-scaling", action="store_true", help="no 1 / 2 worker campaigns")
    args = ap.parse_args()
    dynamics = args.dynamics.split(",")
    if any(d not in ("kinematic", "jsbsim") for d in dynamics):
        ap.error(f"--dynamics {args.dynamics}: allowed kinematic, jsbsim or kinematic,jsbsim")
    torch.set_num_threads(1)
    sc = load_scenario(scenarios_dir() / "encounters.yaml")
    methods = args.methods.split(",")
    seeds = range(1, args.encounters + 1)
    for dyn in dynamics:
        print(f"{dyn} encounters of {sc.name}, seeds {seeds.start}..{seeds.stop - 1}; "
              f"load {os.getloadavg()[0]:.2f} on {os.cpu_count()} CPUs")  # fmt: skip
        print(f"{'method':>14} {'CPU s/enc':>10} {'wall s/enc':>11} {'enc/core-h':>11} "
              f"{'core-h for target':>18}")  # fmt: skip
        for m in methods:
            cpu, wall = per_encounter(sc, m, seeds, dyn)
            print(f"{m:>14} {cpu:10.3f} {wall:11.3f} {3600 / cpu:11.0f} "
                  f"{args.target * cpu / 3600:18.1f}")  # fmt: skip
    if not args.no_scaling:
        scaling(sc, methods[0], dynamics[0], args.encounters * 2, args.ray)


def scaling(sc: Scenario, method: str, dynamics: str, encounters: int, ray: bool) -> None:
    """Wall time of one campaign on 1 and 2 local workers (and a private Ray)."""
    runs = [("1 worker", 1, None), ("2 workers", 2, None)]
    if ray:
        runs.append(("Ray, 2 CPUs", 2, "local"))
    base = None
    for label, workers, address in runs:
        t0 = time.perf_counter()
        run_campaign(sc, [method], [1], encounters, dynamics=dynamics, workers=workers,
                     ray_address=address)  # fmt: skip
        wall = time.perf_counter() - t0
        base = base or wall
        print(f"campaign of {encounters} {method} encounters, {label}: "
              f"{wall:.1f} s wall, speed-up {base / wall:.2f}; load "
              f"{os.getloadavg()[0]:.2f}")  # fmt: skip


if __name__ == "__main__":
    main()
