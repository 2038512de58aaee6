"""Random service problems: user layouts, K, access mode and environment.

The universal D3QN (``universal.py``) trains on these and ``benchmarks/studies/bench_placement.py``
evaluates on them, with disjoint seeds (training draws from ``default_rng([seed, episode])``
with small seeds; the benchmark from ``default_rng([BENCH_SEED, ...])``).

- ``uniform``: K users uniform in the region (as ``comms.users.count`` does).
- ``clustered``: 1-3 cluster centres uniform in the region (50 m in from the edge), users drawn
  around a random centre with a Gaussian spread of 20-60 m, clipped to the region: hot spots,
  where the placement matters most in OFDMA.
"""

from __future__ import annotations

from typing import Literal

import numpy as np

from uavxai.comms.channel import ENVIRONMENTS
from uavxai.scenario import Scenario, default_scenario
from uavxai.service.service_env import ServiceEnv

Kind = Literal["uniform", "clustered"]
KINDS: tuple[str, ...] = ("uniform", "clustered")
ACCESS: tuple[str, ...] = ("shared", "ofdma")
REGION = ((750.0, 1250.0), (750.0, 1250.0))  # the scenario default region
CLUSTER_MARGIN_M = 50.0
CLUSTER_SPREAD_M = (20.0, 60.0)


def draw_layout(rng: np.random.Generator, k: int, kind: str) -> np.ndarray:
    """K user positions ``(K, 2)`` in the default region."""
    lo = np.array([REGION[0][0], REGION[1][0]])
    hi = np.array([REGION[0][1], REGION[1][1]])
    if kind == "uniform":
        return rng.uniform(lo, hi, size=(k, 2))
    if kind != "clustered":
        raise ValueError(f"layout kind {kind!r}; allowed: {', '.join(KINDS)}")
    n = int(rng.integers(1, 4))
    centres = rng.uniform(lo + CLUSTER_MARGIN_M, hi - CLUSTER_MARGIN_M, size=(n, 2))
    spread = rng.uniform(*CLUSTER_SPREAD_M)
    which = rng.integers(0, n, size=k)
    return np.clip(centres[which] + rng.normal(0.0, spread, size=(k, 2)), lo, hi)


def problem_scenario(
    users_xy: np.ndarray, access: str, environment: str, seed: int = 0, fading: str = "none"
) -> Scenario:
    """A default scenario with these users, access mode and environment (fading-free)."""
    return default_scenario(
        "placement",
        seed=seed,
        comms={
            "users": {"positions": [[float(x), float(y)] for x, y in users_xy]},
            "access": access,
            "environment": environment,
            "fading": fading,
        },
    )


def random_problem(rng: np.random.Generator, k_range: tuple[int, int]) -> ServiceEnv:
    """A fresh env: K uniform in ``k_range`` (inclusive), random kind, access, environment."""
    k = int(rng.integers(k_range[0], k_range[1] + 1))
    kind = KINDS[int(rng.integers(len(KINDS)))]
    access = ACCESS[int(rng.integers(len(ACCESS)))]
    environment = list(ENVIRONMENTS)[int(rng.integers(len(ENVIRONMENTS)))]
    users = draw_layout(rng, k, kind)
    return ServiceEnv.from_scenario(problem_scenario(users, access, environment))
