"""An observation of an encounter whose size does not depend on the number of intruders: what
the learned planners' networks see, and what the Gymnasium env
(:class:`uavxai.learning.env.EncounterEnv`) returns.

The ownship's own situation, then the ``n_nearest`` intruders, nearest first, relative to the
ownship in its heading frame (forward, right, up), then for the same intruders in the same
order the distance and time of their closest point of approach at the current relative
velocity. Absent slots are zeros with a ``present`` flag of 0, so 3 or 40 intruders give the
same vector. Distances are scaled by ``SCALE_M``, speeds by the top ownship speed and times by
``TCPA_SCALE_S``, so that every entry is of order one.

The closest approach is a function of the relative position and velocity already in the
observation, but one an MLP learns slowly; handing it over makes the learned baselines better
at the one thing they are compared on, avoiding intruders.
"""

from __future__ import annotations

import math

import numpy as np

from uavxai.avoidance.model import PHI, PHI_CMD, PSI, V, X, Y
from uavxai.avoidance.types import PlannerConfig
from uavxai.geometry import closest_point_of_approach

SCALE_M = 500.0  # distances are divided by this
OWN_FEATURES = 10
INTRUDER_FEATURES = 8  # forward, right, up, v_forward, v_right, v_up, distance, present
CPA_FEATURES = 2  # per intruder slot: distance and time of the closest point of approach
TCPA_SCALE_S = 30.0
TCPA_MAX_S = 120.0
N_NEAREST = 8  # the intruder slots of the shipped networks


def observation_size(n_nearest: int = N_NEAREST) -> int:
    return OWN_FEATURES + (INTRUDER_FEATURES + CPA_FEATURES) * n_nearest


def observe(
    own: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    goal: np.ndarray,
    config: PlannerConfig,
    n_nearest: int = N_NEAREST,
) -> np.ndarray:
    """The observation (float32, ``observation_size(n_nearest)``) of an ownship state row
    ``own`` (encounter-model columns), intruders at ``pos`` (N, 3) moving with ``vel`` (N, 3),
    flying to ``goal`` (3,).

    Own features: goal forward, right, up and distance; speed; bank command and bank (both
    over the bank limit); the distance to the nearest wall; sin and cos of the heading. Then
    ``INTRUDER_FEATURES`` per slot, then ``CPA_FEATURES`` per slot (the order the shipped
    networks were trained on).
    """
    psi = float(own[PSI])
    s, c = math.sin(psi), math.cos(psi)
    v_top = config.speed_mps[1]

    def body(dx: np.ndarray, dy: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return dx * s + dy * c, dx * c - dy * s  # forward, right

    g = np.asarray(goal, dtype=float) - own[:3]
    g_fwd, g_right = body(g[0], g[1])
    wall = min(
        own[X] - config.x_bounds[0],
        config.x_bounds[1] - own[X],
        own[Y] - config.y_bounds[0],
        config.y_bounds[1] - own[Y],
    )
    lim = config.bank_limit_rad
    head = [
        g_fwd / SCALE_M,
        g_right / SCALE_M,
        g[2] / SCALE_M,
        math.sqrt(float(g @ g)) / SCALE_M,
        own[V] / v_top,
        own[PHI_CMD] / lim,
        own[PHI] / lim,
        wall / SCALE_M,
        s,
        c,
    ]
    out = np.zeros(observation_size(n_nearest), dtype=np.float32)
    out[:OWN_FEATURES] = head
    if len(pos) == 0 or n_nearest == 0:
        return out
    rel = np.asarray(pos, dtype=float) - own[:3]
    dist = np.sqrt(np.sum(rel**2, axis=1))
    nearest = np.argsort(dist, kind="stable")[:n_nearest]
    own_vel = np.array([own[V] * s, own[V] * c, 0.0])
    rel_v = np.asarray(vel, dtype=float)[nearest] - own_vel
    fwd, right = body(rel[nearest, 0], rel[nearest, 1])
    v_fwd, v_right = body(rel_v[:, 0], rel_v[:, 1])
    block = np.stack(
        [
            fwd / SCALE_M,
            right / SCALE_M,
            rel[nearest, 2] / SCALE_M,
            v_fwd / v_top,
            v_right / v_top,
            rel_v[:, 2] / v_top,
            dist[nearest] / SCALE_M,
            np.ones(len(nearest)),
        ],
        axis=1,
    )
    out[OWN_FEATURES : OWN_FEATURES + block.size] = block.ravel()
    tcpa, dcpa = closest_point_of_approach(rel[nearest], rel_v, TCPA_MAX_S)
    cpa = OWN_FEATURES + INTRUDER_FEATURES * n_nearest
    out[cpa : cpa + CPA_FEATURES * len(nearest)] = np.stack(
        [dcpa / SCALE_M, tcpa / TCPA_SCALE_S], axis=1
    ).ravel()
    return out
