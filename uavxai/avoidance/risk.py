"""Risk as a probability (issue 31, ``avoidance.mcts.risk: probability``): the chance that a
line loses separation with a track, given the track's Gaussian position error.

Why not the k-sigma wall: a wall of ``uncertainty_k`` sigmas around a vague track fences off
hundreds of metres (257 m 16 s ahead at the median track with poor ADS-B) although the chance
of meeting it is small, so the tree either threads a gap or gives up the mission. Here the
mean track, grown by the reachable-set margin of what the intruder could still do, stays a
hard wall (a line inside it is a collision, as today); the track error is a probability.

The quantity, per intruder and tree edge: at the edge's closest approach to the mean track
(miss ``d``, separation needed ``R`` = d_min plus the reachable margin there, the track's
1-sigma error ``s`` per axis there), the chance that the intruder's error puts it within
``R`` of the line. In the encounter plane (perpendicular to the relative velocity at the
closest approach) a straight pass comes within ``R`` exactly when the error's projection on
that plane lies in the disc of radius ``R`` about the miss point: for an isotropic error,
the Rice distribution's CDF,

    p = integral_0^R (r / s^2) exp(-(r^2 + d^2) / (2 s^2)) I0(r d / s^2) dr,

the short-encounter collision probability of conjunction analysis. It is exact for a long
straight pass with a fixed position error (tests/test_avoidance_risk.py checks it against
Monte Carlo) and the standard approximation when the error grows during the pass.

Combined over intruders and a line's edges as independent events, ``risk = 1 - prod(1 - p)``,
and the line is worth ``(1 - risk)`` times its clear value: the expected value of eq 14 when
losing separation is scored as the collision it would be (value 0). An intruder whose closest
approach on an edge is that edge's first instant is not counted again there (it was counted,
at that same point, on the edge before), so a pass split across two edges counts once.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# Beyond this many sigmas outside the needed separation a track's chance of losing it is taken
# as 0: the Rice CDF there is below 2.3e-4 (its 1-D limit Phi(-3.5)) and smaller still for
# a vague track (R << s). Culling (Track.of's ball) reaches this far, so nothing counted is
# skipped.
RISK_SIGMAS = 3.5
# Gauss-Legendre nodes over the integral's support [max(0, d - 8 s), min(R, d + 8 s)]: the
# integrand is smooth there (a Gaussian in r times a slowly varying factor), and 32 nodes
# give the CDF to about 1e-7 over that width of 16 sigmas, the Bessel factor's accuracy
# (tests/test_avoidance_risk.py compares with 10^5 Monte Carlo samples).
_NODES, _WEIGHTS = np.polynomial.legendre.leggauss(32)
_NODES.flags.writeable = _WEIGHTS.flags.writeable = False
_SUPPORT = 8.0  # sigmas either side of the miss that the integrand is taken over


@njit(cache=True)
def _i0e(x):
    """exp(-x) I0(x) for x >= 0 (Abramowitz and Stegun 9.8.1-9.8.2, relative error < 2e-7)."""
    if x < 3.75:
        t = (x / 3.75) ** 2
        i0 = 1.0 + t * (3.5156229 + t * (3.0899424 + t * (1.2067492 + t * (0.2659732 + t * (
            0.0360768 + t * 0.0045813)))))  # fmt: skip
        return i0 * math.exp(-x)
    t = 3.75 / x
    poly = 0.39894228 + t * (0.01328592 + t * (0.00225319 + t * (-0.00157565 + t * (
        0.00916281 + t * (-0.02057706 + t * (0.02635537 + t * (-0.01647633
        + t * 0.00392377)))))))  # fmt: skip
    return poly / math.sqrt(x)


@njit(cache=True)
def loss_probability(d, radius, sigma):
    """The chance that a pass with miss ``d`` (m) to a track comes within ``radius`` (m) of
    it when the track's position error is Gaussian with ``sigma`` (m, per axis): the Rice
    CDF above. ``sigma`` 0: 1 inside, 0 outside."""
    if sigma <= 0.0:
        return 1.0 if d < radius else 0.0
    if d - radius > RISK_SIGMAS * sigma:
        return 0.0
    if d + _SUPPORT * sigma <= radius:
        return 1.0  # the disc holds all but 1e-15 of the error: 1, not the quadrature's 1 - 1e-7
    lo = max(0.0, d - _SUPPORT * sigma)
    hi = radius
    half, mid = 0.5 * (hi - lo), 0.5 * (hi + lo)
    s2 = sigma * sigma
    total = 0.0
    for k in range(_NODES.size):
        r = mid + half * _NODES[k]
        total += _WEIGHTS[k] * r * math.exp(-((r - d) ** 2) / (2.0 * s2)) * _i0e(r * d / s2)
    return min(max(total * half / s2, 0.0), 1.0)


def loss_probabilities(d: np.ndarray, radius: np.ndarray, sigma: np.ndarray) -> np.ndarray:
    """:func:`loss_probability` element by element over broadcast arrays."""
    arrays = (np.asarray(a, dtype=float) for a in (d, radius, sigma))
    d, radius, sigma = np.broadcast_arrays(*arrays)
    out = np.empty(d.shape)
    flat = out.reshape(-1)
    for i, (a, b, c) in enumerate(zip(d.ravel(), radius.ravel(), sigma.ravel(), strict=True)):
        flat[i] = loss_probability(a, b, c)
    return out


@njit(cache=True)
def edge_loss(sep2, frac, exact, margin, sigma, ids, k, last, first_edge, dmin, out):
    """Per intruder ``ids[:k]``, the chance that one tree edge loses separation with it,
    into ``out[:k]`` (the module docstring): at the instant where the edge comes closest to
    its mean track, net of its margin, up to index ``last``. ``sep2`` (m, k) squared
    distances per instant (``exact`` False, m = n+1) or per sub-step chord, closest point at
    ``frac`` (m, k) along it (``exact`` True, m = n: the chord is held to its end's margin, as
    the collision test holds it); ``margin`` and ``sigma`` (n+1, N) per instant and intruder.
    ``first_edge``: the edge starts at the decision; another edge's start was counted on the
    edge before it, so an intruder closest there counts 0 here."""
    for q in range(k):
        j = ids[q]
        best, bi = np.inf, 0
        for i in range(min(last + 1, sep2.shape[0])):
            g = math.sqrt(sep2[i, q]) - (margin[i + 1, j] if exact else margin[i, j])
            if g < best:
                best, bi = g, i
        at_start = bi == 0 and (not exact or frac[bi, q] == 0.0)
        if at_start and not first_edge:
            out[q] = 0.0
            continue
        if exact:
            f = frac[bi, q]
            s = sigma[bi, j] + f * (sigma[bi + 1, j] - sigma[bi, j])
            need = margin[bi + 1, j]
        else:
            s, need = sigma[bi, j], margin[bi, j]
        out[q] = loss_probability(math.sqrt(sep2[bi, q]), dmin + need, s)
