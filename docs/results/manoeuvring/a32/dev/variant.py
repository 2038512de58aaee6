"""Fly rows with `mcts_sep` under a cornered-rule variant (issue 31, a32's development).

    python variant.py VARIANT SCENARIO.yaml INTRUDERS DYNAMICS SEED...

prints one line per seed: variant, seed, outcome, steps, closest approach (m), the last decision
(step, x, y, h) and how many decisions the cornered rule chose. ``v0`` flies the code's own rule
(what the scenario file sets); the others replace ``uavxai.avoidance.lines.cornered_key`` (the
README beside this file says what each is). With PYTHONPATH at a frozen a31 worktree the
variants were flown on a31's code; with main's, on this commit's.
"""

from __future__ import annotations

import math
import sys

import uavxai.avoidance.lines as lines
from uavxai.campaign.episode import campaign_spec, planner_for
from uavxai.scenario import load_scenario
from uavxai.sim.build import fly

DMIN = 50.0


def _when(c) -> float:
    return -math.inf if c.meets is None else round(c.meets.time_s, 6)


def key_v1(c, by_value=False, *_):
    """The latest meeting, then the line's closest approach to any intruder."""
    sep = c.predicted_min_separation_m
    return (not lines.leaves(c), _when(c), sep, *lines.search_key(c, by_value))


def key_v2(c, by_value=False, *_):
    """A closest approach of d_min or more first, then as v1."""
    sep = c.predicted_min_separation_m
    return (not lines.leaves(c), sep >= DMIN, _when(c), sep, *lines.search_key(c, by_value))


def key_v3(c, by_value=False, *_):
    """The closest approach (uncapped), then the latest meeting."""
    sep = c.predicted_min_separation_m
    return (not lines.leaves(c), sep, _when(c), *lines.search_key(c, by_value))


def key_v4(c, by_value=False, *_):
    """The closest approach up to 2 d_min, then the latest meeting, then the closest approach:
    what `cornered_rule: widest` became."""
    sep = c.predicted_min_separation_m
    width = min(sep, 2 * DMIN)
    return (not lines.leaves(c), width, _when(c), sep, *lines.search_key(c, by_value))


def key_v5(c, by_value=False, *_):
    """The closest approach up to 2 d_min, then the search's own order (no latest meeting)."""
    width = min(c.predicted_min_separation_m, 2 * DMIN)
    return (not lines.leaves(c), width, *lines.search_key(c, by_value))


KEYS = {"v1": key_v1, "v2": key_v2, "v3": key_v3, "v4": key_v4, "v5": key_v5}


def main(argv: list[str]) -> None:
    variant, path, n, dynamics, *seeds = argv
    scenario = load_scenario(path)
    if variant != "v0":
        lines.cornered_key = KEYS[variant]
    for seed in seeds:
        planner = planner_for(scenario, "mcts_sep")
        planner.__dict__.pop("plan", None)
        plan, last = planner.plan, []

        def record(own, intruders, goal, *, step, _plan=plan, _last=last, **kw):
            d = _plan(own, intruders, goal, step=step, **kw)
            _last.append((step, round(own.x), round(own.y), round(own.h), d.cornered))
            return d

        planner.plan = record
        r = fly(campaign_spec(scenario, int(n), int(seed), dynamics), planner)
        cornered = sum(1 for x in last if x[4])
        print(variant, seed, r.outcome.value, r.steps, round(r.min_separation_m, 1), "last",
              last[-1][:4], "cornered", cornered, flush=True)  # fmt: skip


if __name__ == "__main__":
    main(sys.argv[1:])
