"""The paper's random baseline: random points of the search area, random power levels.

Each of ``evaluations`` draws is a lattice position (uniform per axis over the points the moves
can reach) and a uniform level per user; the best draw by the fading-free objective is the
service point (the hover objective, or ``score``'s: the orbit objective of
``service.platform: orbit``). With the same budget as the learned agents' ``service.steps``,
it shows what a search without learning finds.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from uavxai.service.d3qn import Episode
from uavxai.service.service_env import ServiceEnv, levels_to_power

Score = Callable[[np.ndarray, np.ndarray], np.ndarray]  # (positions (M,3), levels (M,K)) -> (M,)


def random_search(
    env: ServiceEnv, evaluations: int, rng: np.random.Generator, score: Score | None = None
) -> Episode:
    axes = env.space.axes()
    positions = np.column_stack([rng.choice(axis, size=evaluations) for axis in axes])
    levels = rng.integers(0, env.power_levels, size=(evaluations, env.channel.k))
    power = levels_to_power(levels, env.channel.p_max_w, env.power_levels)
    if score is None:
        objective = env.channel.evaluate(positions, power).objective
    else:
        objective = score(positions, levels)
    best = int(np.argmax(objective))
    return Episode(
        objective=float(objective[best]),
        position=positions[best],
        levels=levels[best],
        path=positions,
        ret=float(objective.sum()),
    )
