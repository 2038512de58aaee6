"""Cost and quality of MCTS against the exhaustive search it samples (issue 31's "Speed").

On one fixed set of seeded encounters per traffic density (20 and 40 intruders by default,
the default scenario's area, the ownship at a random place and heading): the decision time
of ``mcts`` (the paper's nine actions) and ``mcts_vertical`` (eleven, with climb and
descend) at 200 simulations, depth 4 (p50, p95; the goal is p50 <= 10 ms CPU at 20 intruders
and <= 25 ms at 40), and of exhaustive search over the same action set to the same depth,
measured on the same encounters in the same process. Then whole kinematic episodes of each
MCTS planner and of its exhaustive reference on the same seeds: outcomes, collision counts,
mean steps and the steps ratio MCTS / exhaustive (the goal: within 10 %, with the same
safety).

Times are the process's CPU time per decision (less disturbed by other processes than wall
time, which is printed too); the load average is printed beside them.

    .venv/bin/python benchmarks/performance/bench_mcts.py [--quick] [--encounters 40]
        [--episodes 20] [--baseline DIR]
        [--intruders 20,40] [--simulations 200] [--depth 4] [--repeats 5] [--no-vertical] [--sep]
        [--risk margin|probability] [--track-error 2.9,2.4] [--mcts KEY=VALUE ...]

``--baseline DIR`` times the MCTS planners of another source tree too (a checkout of the
code before a change, first on the path of a child process that builds the same encounters),
its pass and this process's pass alternating repeat by repeat, so both see the same load; it
prints each planner's p50 against the baseline's and their ratio (issue 31: "before/after,
alternately").

``--risk`` sets ``avoidance.mcts.risk`` (issue 31: the track error as a probability in the
value, not a wall); ``--track-error M,V`` gives every encounter's intruders that 1-sigma
position (m) and velocity (m/s) error (default: none, the exact states; 2.9,2.4 is the
median of the default ADS-B picture's tracks, 22,7.9 the poor picture's, docs/results), the
error the probability weighs. The episodes fly the scenario's own picture.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import math
import os
import subprocess
import sys
import time

import numpy as np

from uavxai.avoidance import PlannerConfig, make_planner
from uavxai.avoidance.exhaustive import ExhaustivePlanner
from uavxai.avoidance.types import Ownship, Planner
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.sim.build import open_world
from uavxai.sim.build import run_kinematic as run_episode
from uavxai.sim.spec import episode_spec
from uavxai.surveillance.tracker import truth_beliefs
from uavxai.vocabulary import RISK_MODELS

DECISION_GOAL_MS = {20: 10.0, 40: 25.0}  # issue 31: MCTS decision p50, CPU, by intruders


def encounters(
    scenario, count: int, n_intruders: int, error: tuple[float, float] = (0.0, 0.0)
) -> list[tuple[Ownship, list, tuple]]:
    """Seeded encounters: (ownship, intruders with the track ``error`` (m, m/s), goal)."""
    out = []
    for seed in range(count):
        rng = np.random.default_rng(1000 + seed)
        own = Ownship(
            x=float(rng.uniform(200, 1800)),
            y=float(rng.uniform(200, 1800)),
            h=float(rng.uniform(100, 140)),
            speed=float(rng.uniform(15, 28)),
            heading=float(rng.uniform(0, 2 * math.pi)),
            bank=math.radians(float(rng.choice([-20, -10, 0, 10, 20]))),
        )
        spec = episode_spec(scenario, seed, n_intruders=n_intruders)
        with open_world(spec) as world:
            beliefs = [dataclasses.replace(i, sigma_m=error[0], sigma_v=error[1])
                       for i in truth_beliefs(world.state())]  # fmt: skip
            out.append((own, beliefs, spec.goal))
    return out


def time_decisions(planner, cases, repeats: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-case CPU ms and wall ms (best of ``repeats``)."""
    cpu = np.full(len(cases), np.inf)
    wall = np.full(len(cases), np.inf)
    for _ in range(repeats):
        for i, (own, intruders, goal) in enumerate(cases):
            planner.reset(i)
            t_cpu, t_wall = time.process_time(), time.perf_counter()
            planner.plan(own, intruders, goal)
            cpu[i] = min(cpu[i], 1000 * (time.process_time() - t_cpu))
            wall[i] = min(wall[i], 1000 * (time.perf_counter() - t_wall))
    return cpu, wall


def pairs(cfg: PlannerConfig, vertical: bool, sep: bool = False) -> list[tuple[Planner, Planner]]:
    """(MCTS planner, its exhaustive reference over the same action set). ``sep``: `mcts_sep`
    too, against the vertical set's reference, which weighs neither NMAC intrusion nor walls
    (the agreement then says how far those terms move the choice)."""
    out = [(make_planner("mcts", cfg), make_planner("exhaustive", cfg))]
    if vertical or sep:
        vcfg = dataclasses.replace(cfg, actions="vertical")
        reference = ExhaustivePlanner(vcfg, name="exhaustive_vertical")
        out.append((make_planner("mcts_vertical", cfg), reference))
        if sep:
            out.append((make_planner("mcts_sep", cfg), reference))
    return out


def report_times(name: str, cpu: np.ndarray, wall: np.ndarray) -> None:
    p50, p95 = np.percentile(cpu, [50, 95])
    w50, w95 = np.percentile(wall, [50, 95])
    print(
        f"  {name:<20} decision ms  cpu p50 {p50:7.2f}  p95 {p95:7.2f}   "
        f"(wall p50 {w50:7.2f}  p95 {w95:7.2f})"
    )


def against_optimum(mcts: Planner, exhaustive: Planner, cases) -> None:
    """MCTS's choice scored by exhaustive search: the best value reachable after it."""
    agree, unsafe, regret = 0, 0, []
    for i, case in enumerate(cases):
        mcts.reset(i)
        chosen = mcts.plan(*case).action
        best = exhaustive.plan(*case)
        q = {c.action: c.q for c in best.children}
        agree += chosen == best.action
        unsafe += q[chosen] == 0.0 and max(q.values()) > 0.0
        regret.append(max(q.values()) - q[chosen])
    print(
        f"  {mcts.name} against the optimum: same action {agree}/{len(cases)}, value regret "
        f"mean {np.mean(regret):.4f} max {np.max(regret):.4f}, colliding choices with a safe "
        f"one available {unsafe}"
    )


def episodes(planner: Planner, scenario, n_intruders: int, count: int, first: int = 0) -> dict:
    """Outcome counts and mean steps of ``count`` seeded kinematic episodes from ``first``."""
    results = [run_episode(planner, scenario, seed, n_intruders)
               for seed in range(first, first + count)]  # fmt: skip
    outcomes = [r.outcome for r in results]
    out = {k: outcomes.count(k) for k in ("goal", "collision", "out_of_bounds", "timeout")}
    out["steps"] = float(np.mean([r.steps for r in results]))
    print(
        f"  {planner.name:<20} goal {out['goal']}/{count}  collision {out['collision']}  "
        f"out of bounds {out['out_of_bounds']}  timeout {out['timeout']}  "
        f"mean steps {out['steps']:.1f}"
    )
    return out


def setup(args, n_intruders: int):
    """(scenario, encounters, planner pairs, warmed) at one traffic density."""
    try:
        scenario = default_scenario(
            "bench-mcts",
            intruders={"count": n_intruders},
            avoidance={"mcts": {"simulations": args.simulations, "depth": args.depth,
                                "risk": args.risk, **args.mcts}},  # fmt: skip
        )
    except UserError as exc:  # a bad --mcts setting: the scenario's own message, no traceback
        sys.exit(f"bench_mcts.py: {exc}")
    cfg = PlannerConfig.from_scenario(scenario)
    cases = encounters(scenario, args.encounters, n_intruders, args.track_error)
    planners = pairs(cfg, not args.no_vertical, args.sep)
    for pair in planners:
        for planner in pair:  # warm caches and imports
            planner.plan(*cases[0])
    return scenario, cases, planners


def child_times(args, n_intruders: int) -> None:
    """The child of ``--baseline``: one timing pass of the MCTS planners, as JSON."""
    _, cases, planners = setup(args, n_intruders)
    import uavxai

    out = {"uavxai": uavxai.__file__}
    for mcts, _ in planners:
        out[mcts.name] = time_decisions(mcts, cases, 1)[0].tolist()
    print(json.dumps(out))


def against_baseline(args, n_intruders: int, cfg: PlannerConfig, cases) -> None:
    """This tree's MCTS planners and ``args.baseline``'s, timed alternately (module doc).
    Each pass, on either side, flies fresh planners warmed on the first encounter only, as
    the child does: the motions of every other encounter are computed, not memoised."""
    names = [m.name for m, _ in pairs(cfg, not args.no_vertical, args.sep)]
    own = {name: np.full(len(cases), np.inf) for name in names}
    base = {name: np.full(len(cases), np.inf) for name in names}
    argv = [sys.executable, os.path.abspath(__file__), "--child-times", "--intruders",
            str(n_intruders), "--encounters", str(len(cases)), "--simulations",
            str(args.simulations), "--depth", str(args.depth), "--risk", args.risk,
            "--track-error", ",".join(str(e) for e in args.track_error)]  # fmt: skip
    if args.no_vertical:
        argv.append("--no-vertical")
    if args.sep:
        argv.append("--sep")
    argv += [f"--mcts={k}={v}" for k, v in args.mcts.items()]
    env = {**os.environ, "PYTHONPATH": os.path.abspath(args.baseline)}
    for _ in range(args.repeats):
        for mcts, _ in pairs(cfg, not args.no_vertical, args.sep):
            mcts.plan(*cases[0])
            own[mcts.name] = np.minimum(own[mcts.name], time_decisions(mcts, cases, 1)[0])
        done = subprocess.run(argv, env=env, capture_output=True, text=True)
        if done.returncode:  # the baseline tree's own error (an option it lacks, a bad path)
            tail = "\n".join(done.stderr.strip().splitlines()[-5:])
            sys.exit(f"bench_mcts.py: the baseline {args.baseline} failed "
                     f"(exit {done.returncode}):\n{tail}")  # fmt: skip
        theirs = json.loads(done.stdout.strip().splitlines()[-1])
        for name in base:
            base[name] = np.minimum(base[name], theirs[name])
    print(f"  against the baseline {theirs['uavxai']} ({args.repeats} alternating repeats, "
          f"load average now {os.getloadavg()[0]:.2f}):")  # fmt: skip
    for name in own:
        mine, before = np.percentile(own[name], 50), np.percentile(base[name], 50)
        print(f"  {name:<20} cpu p50 {mine:7.2f} ms, baseline {before:7.2f} ms, "
              f"ratio {mine / before:.3f}")  # fmt: skip


def density(args, n_intruders: int) -> None:
    """Everything measured at one traffic density."""
    scenario, cases, planners = setup(args, n_intruders)
    print(
        f"{n_intruders} intruders, {len(cases)} encounters, MCTS {args.simulations} simulations, "
        f"depth {args.depth}, risk {args.risk}, track error {args.track_error}, "
        f"settings {args.mcts or 'default'} "
        f"(load average {os.getloadavg()[0]:.2f})"
    )
    for mcts, exhaustive in planners:
        m_cpu, m_wall = time_decisions(mcts, cases, args.repeats)
        e_cpu, e_wall = time_decisions(exhaustive, cases, args.repeats)
        report_times(mcts.name, m_cpu, m_wall)
        report_times(exhaustive.name, e_cpu, e_wall)
        ratio = m_cpu.sum() / e_cpu.sum()
        print(f"  cost ratio {mcts.name} / {exhaustive.name} (cpu): {ratio:.3f}")
        against_optimum(mcts, exhaustive, cases)
        goal = DECISION_GOAL_MS.get(n_intruders)
        if goal is not None:
            share = np.percentile(m_cpu, 50) / goal
            print(f"  {mcts.name} cpu p50 / its goal of {goal:.0f} ms: {share:.2f}")
    if args.baseline:
        against_baseline(args, n_intruders, PlannerConfig.from_scenario(scenario), cases)
    if not args.episodes:
        return
    last = args.seed + args.episodes - 1
    print(f"  {args.episodes} kinematic episodes each (seeds {args.seed}..{last}):")
    for mcts, exhaustive in planners:
        m = episodes(mcts, scenario, n_intruders, args.episodes, args.seed)
        e = episodes(exhaustive, scenario, n_intruders, args.episodes, args.seed)
        print(
            f"  steps ratio {mcts.name} / {exhaustive.name}: {m['steps'] / e['steps']:.3f}; "
            f"collisions {m['collision']} vs {e['collision']}"
        )


def _setting(ap: argparse.ArgumentParser, kv: str) -> tuple[str, object]:
    """``--mcts KEY=VALUE``: a number where it reads as one (the scenario checks the rest)."""
    key, sep, value = kv.partition("=")
    if not sep or not key:
        ap.error(f"--mcts: KEY=VALUE, e.g. backup=best, got {kv!r}")
    if key in ("simulations", "depth", "risk"):
        ap.error(f"--mcts {key}=...: give it as --{key}, which the report prints")
    try:
        return key, float(value)
    except ValueError:
        return key, value


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawTextHelpFormatter)
    ap.add_argument("--quick", action="store_true", help="10 encounters, 4 episodes, 1 repeat")
    ap.add_argument("--encounters", type=int, default=40)
    ap.add_argument("--episodes", type=int, default=20)
    ap.add_argument("--seed", type=int, default=0, help="the episodes' first seed")
    ap.add_argument("--intruders", default="20,40", help="comma-separated traffic densities")
    ap.add_argument("--simulations", type=int, default=200)
    ap.add_argument("--depth", type=int, default=4)
    ap.add_argument("--repeats", type=int, default=5, help="timing repeats (best is kept)")
    ap.add_argument("--no-vertical", action="store_true", help="the paper's nine actions only")
    ap.add_argument("--sep", action="store_true", help="mcts_sep too (issues 27, 31)")
    ap.add_argument("--risk", choices=RISK_MODELS, default="margin",
                    help="avoidance.mcts.risk (default: margin)")  # fmt: skip
    ap.add_argument("--track-error", default="0,0",
                    help="intruders' 1-sigma position m, velocity m/s errors")  # fmt: skip
    ap.add_argument("--mcts", action="append", default=[], metavar="KEY=VALUE",
                    help="an avoidance.mcts setting, e.g. backup=best (repeatable)")  # fmt: skip
    ap.add_argument("--baseline", metavar="DIR",
                    help="a source tree whose MCTS planners are timed alternately")  # fmt: skip
    ap.add_argument("--child-times", action="store_true", help=argparse.SUPPRESS)
    args = ap.parse_args()
    try:
        args.track_error = tuple(float(x) for x in args.track_error.split(","))
    except ValueError:
        args.track_error = ()
    if len(args.track_error) != 2 or min(args.track_error) < 0:
        ap.error("--track-error: two numbers >= 0, position m and velocity m/s (2.9,2.4)")
    args.mcts = dict(_setting(ap, kv) for kv in args.mcts)
    if args.seed < 0:
        ap.error(f"--seed: the episodes' first seed, a whole number >= 0, got {args.seed}")
    if args.quick:
        args.encounters, args.episodes, args.repeats = 10, 4, 1
    try:
        counts = [int(n) for n in args.intruders.split(",")]
    except ValueError:
        ap.error(f"--intruders: comma-separated whole numbers (20,40), got {args.intruders!r}")
    if args.baseline and not os.path.isdir(os.path.join(args.baseline, "uavxai")):
        ap.error(f"--baseline: a source tree holding the uavxai package, got {args.baseline!r}")
    for n in counts:
        child_times(args, n) if args.child_times else density(args, n)


if __name__ == "__main__":
    main()
