"""How far the tree planners' ownship model strays from the aircraft JSBSim flies, by
turbulence severity: the numbers behind ``avoidance.mcts.own_error_10s_m`` (docs/scenario.md).

Flies ``mcts_vertical`` episodes of scenarios/manoeuvring.yaml in JSBSim (seeds 1000 on, not
the evaluation's 0-199), then from every second decision replays the actions the planner
actually chose, one decision period each, through its own encounter model (the planner's
prediction of the path it flew, open loop) and compares with where the aircraft was. Prints
the per-axis error (RMS / sqrt 2) at 4, 8, 12 and 16 s, and ``sigma10``: a t^1.5 law (the
position error of a random acceleration) fitted to them, the error 10 s ahead. Asserts nothing.

    .venv/bin/python benchmarks/studies/bench_own_model.py [--episodes 4] [--intruders 20]
"""

from __future__ import annotations

import argparse

import numpy as np

from uavxai.avoidance.model import model_drift
from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.paths import scenarios_dir
from uavxai.scenario import load_scenario
from uavxai.sim.build import fly
from uavxai.sim.observers import OwnPath
from uavxai.sim.spec import episode_spec

HORIZONS_S = (4, 8, 12, 16)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--episodes", type=int, default=4)
    parser.add_argument("--intruders", type=int, default=20)
    args = parser.parse_args()
    base = load_scenario(scenarios_dir() / "manoeuvring.yaml")
    print(f"{'turbulence':10s} " + " ".join(f"{h:>5d}s" for h in HORIZONS_S) + "  sigma10 (m)")
    for severity in ("none", "light", "moderate", "severe"):
        env = base.environment.model_copy(update={"turbulence": severity})
        pooled: dict[int, list] = {h: [] for h in HORIZONS_S}
        for seed in range(1000, 1000 + args.episodes):
            sc = base.model_copy(update={"environment": env}).with_seed(seed)
            # measure the model as it is, without any own-error margin steering the flight
            cfg = PlannerConfig.from_scenario(sc, own_error_10s_m=0.0)
            log = OwnPath()
            spec = episode_spec(sc, n_intruders=args.intruders, dynamics="jsbsim")
            fly(spec, make_planner("mcts_vertical", cfg), observers=[log])
            goal = np.asarray(spec.goal)
            drift = model_drift(cfg, log.own, log.actions, goal, HORIZONS_S, every=2)
            for h, e in drift.items():
                pooled[h].extend(e)
        sigma = np.array([np.sqrt(np.mean(np.square(pooled[h])) / 2) for h in HORIZONS_S])
        t = np.array(HORIZONS_S, dtype=float)
        fit = float(np.sum(sigma * t**1.5) / np.sum(t**3))  # least squares of sigma = a t^1.5
        print(f"{severity:10s} " + " ".join(f"{s:6.1f}" for s in sigma) + f"  {fit * 10**1.5:6.1f}")


if __name__ == "__main__":
    main()
