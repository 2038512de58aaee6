"""Made-up but plausible runs for exercising the recorder without JSBSim or a planner.

Used by the recording tests, the recording benchmark (benchmarks/performance/) and to render
the docs screenshot (it lives in the package so those need no path to tests/): the
ownship weaves towards its goal, intruders fly straight lines, and every decision carries a
hand-built search tree whose statistics look like an MCTS's (visits concentrated on a few
actions, Q in [0, 1], collisions where the predicted separation is small).
"""

from __future__ import annotations

import math
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from uavxai.avoidance.types import ChildStats, Decision, SearchTree
from uavxai.dynamics.state import OWNSHIP_ID, TrafficState, intruder_id
from uavxai.units import G
from uavxai.vocabulary import ACCEL_SIGNS, BANK_SIGNS, N_ACTIONS, action_name

if TYPE_CHECKING:
    from uavxai.recording.recorder import RunRecorder

BOUNDS = {"x": (0.0, 2000.0), "y": (0.0, 2000.0), "h": (50.0, 300.0)}
GOAL = np.array([1000.0, 1000.0, 120.0])


def traffic(
    n_intruders: int, duration_s: float, rate_hz: float = 10.0, seed: int = 0
) -> Iterator[TrafficState]:
    """TrafficStates every 1/rate_hz s: row 0 the ownship, then ``intruder-1..N``."""
    rng = np.random.default_rng(seed)
    n = n_intruders + 1
    ids = (OWNSHIP_ID, *(intruder_id(i + 1) for i in range(n_intruders)))
    pos = np.empty((n, 3))
    pos[0] = (100.0, 100.0, 120.0)
    # Intruders start on a ring round the area's centre and cross it, so encounters happen.
    bearing = rng.uniform(0.0, 2 * math.pi, n_intruders)
    pos[1:, 0] = 1000.0 + 850.0 * np.sin(bearing)
    pos[1:, 1] = 1000.0 + 850.0 * np.cos(bearing)
    pos[1:, 2] = rng.uniform(100.0, 140.0, size=n_intruders)
    speed = np.concatenate([[20.0], rng.uniform(15.0, 30.0, n_intruders)])
    inbound = bearing + math.pi + rng.uniform(-0.5, 0.5, n_intruders)
    psi = np.concatenate([[math.radians(45.0)], inbound])
    dt = 1.0 / rate_hz
    for step in range(int(round(duration_s * rate_hz)) + 1):
        t = step * dt
        # The ownship weaves about its course; the bank is what that turn rate needs.
        turn_rate = np.zeros(n)
        turn_rate[0] = math.radians(20.0) / 15.0 * math.cos(t / 15.0)
        phi = np.arctan(speed * turn_rate / G)
        vel = np.stack([speed * np.sin(psi), speed * np.cos(psi), np.zeros(n)], axis=1)
        att = np.stack([phi, np.zeros(n), psi], axis=1)
        yield TrafficState(t, ids, pos.copy(), vel, att, speed.copy())
        pos += vel * dt
        psi = psi + turn_rate * dt


def decision(state: TrafficState, k: int, seed: int = 0, simulations: int = 200) -> Decision:
    """A decision with a two-level search tree (root, 9 actions, 9 below each)."""
    rng = np.random.default_rng([seed, k])
    parent, action, depth = [-1], [-1], [0]
    for a in range(N_ACTIONS):
        parent.append(0)
        action.append(a)
        depth.append(1)
    for child in range(1, N_ACTIONS + 1):
        for a in range(N_ACTIONS):
            parent.append(child)
            action.append(a)
            depth.append(2)
    m = len(parent)
    visits = np.zeros(m, dtype=np.int64)
    visits[0] = simulations
    # Visits follow a peaked preference, as UCT concentrates them; some actions get none.
    visits[1:10] = rng.multinomial(simulations - 1, rng.dirichlet(np.full(N_ACTIONS, 0.4)))
    for child in range(1, 10):
        kids = slice(10 + (child - 1) * 9, 10 + child * 9)
        if visits[child] > 1:
            visits[kids] = rng.multinomial(visits[child] - 1, rng.dirichlet(np.full(9, 0.4)))
    q = rng.uniform(0.2, 0.9, m)
    min_sep = rng.uniform(20.0, 400.0, m)
    terminal = np.where(min_sep < 50.0, 2, 0).astype(np.int8)
    tree = SearchTree(
        parent=np.asarray(parent),
        action=np.asarray(action),
        depth=np.asarray(depth),
        visits=visits,
        value_sum=q * visits,
        min_sep=min_sep,
        closest=rng.integers(0, max(state.n - 1, 1), m),
        terminal=terminal,
        pos=np.repeat(state.pos[:1], m, axis=0),
    )
    best = int(np.argmax(visits[1:10]))
    children = [
        ChildStats(
            action=a,
            bank_cmd_rad=math.radians(10.0) * BANK_SIGNS[a // 3],
            accel_mps2=1.0 * ACCEL_SIGNS[a % 3],
            visits=int(visits[1 + a]),
            q=float(q[1 + a]),
            predicted_min_separation_m=float(min_sep[1 + a]),
            closest_intruder=int(tree.closest[1 + a]),
        )
        for a in range(N_ACTIONS)
    ]
    chosen = children[best]
    return Decision(
        bank_cmd_rad=chosen.bank_cmd_rad,
        accel_mps2=chosen.accel_mps2,
        action=best,
        children=children,
        words=(
            f"Chose '{action_name(best)}': it keeps {chosen.predicted_min_separation_m:.0f} m "
            f"from intruder-{chosen.closest_intruder + 1}, with {chosen.visits} of "
            f"{simulations} simulations.",
            "",
        ),
        tree=tree,
        plan=_plan(state),
        predicted_min_separation_m=chosen.predicted_min_separation_m,
        confidence=chosen.visits / simulations,
        ms=float(rng.uniform(5.0, 15.0)),
    )


def _plan(state: TrafficState, horizon_s: float = 16.0, points: int = 5) -> np.ndarray:
    """The ownship's straight-line projection, standing in for the chosen branch's path."""
    s = np.linspace(0.0, horizon_s, points)[:, None]
    return state.pos[0] + s * state.vel[0]


def users(k: int = 10, seed: int = 0) -> np.ndarray:
    """``k`` ground users uniform in the middle quarter of the area, at h = 0."""
    rng = np.random.default_rng(seed)
    xy = rng.uniform(750.0, 1250.0, size=(k, 2))
    return np.column_stack([xy, np.zeros(k)])


def write_demo(path: Path, n_intruders: int = 20, duration_s: float = 120.0) -> None:
    """A synthetic run recorded with RunRecorder, e.g. to look at the default layout."""
    from uavxai.recording.recorder import RunRecorder  # the recorder is what is exercised

    ids = [intruder_id(i + 1) for i in range(n_intruders)]
    service_point = np.array([1000.0, 1000.0, 120.0])
    search = service_point + np.cumsum(np.random.default_rng(1).normal(0, 10, (30, 3)), axis=0)
    with RunRecorder(path, recording_name="uavxai-synthetic") as rec:
        rec.log_setup(BOUNDS, users(), service_point, search, ids, GOAL)
        for i, state in enumerate(traffic(n_intruders, duration_s)):
            rec.log_traffic(state)
            if i % 10 == 0:
                log_decision(rec, i // 10, state, decision(state, i // 10), ids)


def log_decision(
    rec: RunRecorder,
    k: int,
    state: TrafficState,
    d: Decision,
    ids: list[str],
    sum_rate_bps: float = 2.3e7,
) -> None:
    """Decision ``k`` and the metrics logged beside it, as a run logs them once a period."""
    rec.log_decision(k, state.t, d, ids)
    rec.log_metrics(
        state.t,
        sum_rate_bps=sum_rate_bps,
        min_separation_m=state.min_separation(),
        bank_deg=math.degrees(state.att[0, 0]),
        airspeed_mps=float(state.airspeed[0]),
        decision_ms=d.ms,
    )


if __name__ == "__main__":
    import sys

    write_demo(Path(sys.argv[1] if len(sys.argv) > 1 else "synthetic.rrd"))
