"""Plane and space geometry used everywhere, written once. Headings are radians clockwise
from north (aviation); positions are local ENU metres."""

from __future__ import annotations

import math
from typing import overload

import numpy as np


@overload
def wrap_angle(angle: float) -> float: ...
@overload
def wrap_angle(angle: np.ndarray) -> np.ndarray: ...
def wrap_angle(angle: float | np.ndarray) -> float | np.ndarray:
    """``angle`` in (-pi, pi], element-wise for an array. Through atan2, not a modulo: a
    small angle comes back to the last bit (``(a + pi) % 2pi - pi`` rounds it to pi's ulp)."""
    if isinstance(angle, np.ndarray):
        return np.arctan2(np.sin(angle), np.cos(angle))
    return math.atan2(math.sin(angle), math.cos(angle))


def bearing(dx: float, dy: float) -> float:
    """Direction of the vector (dx east, dy north), clockwise from north, rad."""
    return math.atan2(dx, dy)


def closest_approach(p0: np.ndarray, p1: np.ndarray, q0: np.ndarray, q1: np.ndarray) -> float:
    """Smallest distance between one point moving p0 -> p1 and each of N points moving
    q0 -> q1 ((N, 3) arrays), all linearly over the same interval; inf with N = 0.

    Between two samples a pass-through that neither sample shows is still caught: this is the
    collision test of every episode, whatever the dynamics.
    """
    if len(q0) == 0:
        return math.inf
    d0 = q0 - p0
    dv = (q1 - p1) - d0
    a = np.einsum("ij,ij->i", dv, dv)
    s = np.clip(-np.einsum("ij,ij->i", d0, dv) / np.where(a > 0, a, 1.0), 0.0, 1.0)
    closest = d0 + s[:, None] * dv
    return float(np.sqrt(np.min(np.einsum("ij,ij->i", closest, closest))))
