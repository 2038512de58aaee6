"""MCTS compiled: the simulation loop of :func:`uavxai.avoidance.mcts.search` and the node
expansion of :class:`uavxai.avoidance.mcts.TreeBuilder` over
:meth:`uavxai.avoidance.model.EncounterModel.expand`, in one numba kernel.

Why: a decision walks 200 simulations and expands ~270 nodes; in Python and numpy each
expansion cost ~0.1-0.3 ms of interpreter and small-array overhead (issue 31 measured 39 ms
a decision against a goal of 10). The kernel does the model's arithmetic, in the same order,
per number: every node it expands has the children that ``TreeBuilder.expand`` (the Python
expansion the exhaustive search builds its tree with) gives that node, which
``tests/test_avoidance_kernel.py`` checks node by node, so explanations read the same tree.
What it needs from Python comes in arrays, once per decision: the body motions a search can
expand (:meth:`EncounterModel.motions`), the intruders' tracks per tree level, the tie-break
draws. The first call compiles it (seconds); numba caches the result beside this file.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence

import numpy as np
from numba import njit

from uavxai.avoidance.model import EncounterModel, Track
from uavxai.avoidance.risk import edge_loss
from uavxai.avoidance.types import PlannerConfig, SearchTree
from uavxai.units import G

# Columns of the per-key table ``bend`` (per action) and ``bscal`` (per key).
ZRE, ZIM, DPSI, VEND, PHIEND, PHICMD, RISEEND = range(7)
BALLRE, BALLIM, BALLR, OWNSTEP = range(4)
# Entries of ``par``.
(DMIN, GOALR, XB0, XB1, YB0, YB1, HB0, HB1, CLIMB, DUR, TLEFT, LATE, DMAX, VERT, TDOWN, TLEVEL,
 TUP, GX, GY, GH, CULL, ASPECT, RISK, NMACW, NMACH, NMACV, WALLT, TURNG,
 ROLLT, BEST, GDELAY, VSCALED, HSCALE, PINT) = range(34)  # fmt: skip
_TAU = 2.0 * math.pi
GOAL_DELAY = 1e-4  # value of reaching the goal one tree level later (a tie-break, goal_delay)
_NONE, _GOAL, _COLLISION, _OUT, _TIMEOUT = 0, 1, 2, 3, 4


@njit(cache=True)
def _near(tc, tr, lvl, cx, cy, ch, distance, out):
    """Track.near: intruders whose path ball may come within ``distance`` of the centre."""
    k = 0
    for j in range(tr.shape[1]):
        r = tr[lvl, j]
        if (tc[lvl, j, 0] - cx) ** 2 + (tc[lvl, j, 1] - cy) ** 2 + (tc[lvl, j, 2] - ch) ** 2 <= (
            distance + r
        ) ** 2:
            out[k] = j
            k += 1
    return k


@njit(cache=True)
def _chord(r0x, r0y, r0h, r1x, r1y, r1h, d2):
    """_closest_on_chords for one sub-step: (squared closest distance, its fraction)."""
    dx, dy, dh = r1x - r0x, r1y - r0y, r1h - r0h
    a = dx**2 + dy**2 + dh**2
    b = (r0x * dx + r0y * dy) + r0h * dh
    s = min(max(-b / max(a, 1e-12), 0.0), 1.0)
    return max(d2 + s * (2.0 * b + s * a), 0.0), s


@njit(cache=True)
def _cylinder_chord(x0, y0, h0, x1, y1, h1):
    """uavxai.geometry.cylinder_closest for one sub-step (heights scaled): (squared cylinder
    norm of the closest approach, its fraction); the same candidates in the same order."""
    dx, dy, dh = x1 - x0, y1 - y0, h1 - h0
    a = dx * dx + dy * dy
    b = x0 * dx + y0 * dy
    c = x0 * x0 + y0 * y0
    qa, qb, qc = a - dh * dh, b - h0 * dh, c - h0 * h0
    sq = math.sqrt(max(qb * qb - qa * qc, 0.0))
    nums = (0.0, 1.0, -b, -h0, -qb + sq, -qb - sq, qc, qc)
    dens = (1.0, 1.0, a, dh, qa, qa, -qb - sq, -qb + sq)
    best, best_s = np.inf, 0.0
    for j in range(8):
        s = nums[j] / dens[j] if dens[j] != 0 else 0.0
        s = min(max(s, 0.0), 1.0)
        px, py, ph = x0 + s * dx, y0 + s * dy, h0 + s * dh
        n2 = max(px * px + py * py, ph * ph)
        if n2 < best:
            best, best_s = n2, s
    return best, best_s


@njit(cache=True)
def _hits(xy, hs, txy, th, tm, lvl, ids, k, own_step, step_max, margined, dmin, aspect, k_hit,
          tv, tvmax, scaled):  # fmt: skip
    """EncounterModel._intruder_hits and _closest_approach's inputs for K rows against the
    ``k`` intruders ``ids``: fills ``k_hit``; returns (sep2, frac, exact). ``aspect`` > 0:
    in the conflict cylinder's norm (0: the sphere's 3-D distance). ``scaled`` (the sphere
    with a vertical margin of its own, Track.vscale): height differences stretched by ``tv``
    (a chord's by the smaller of its two ends', a sample's by the smallest of the chords'
    beside it: the smaller, the taller the volume), at most ``tvmax``, so that the sphere of
    d_min + margin in that norm is the spheroid."""
    rows, m = xy.shape[0], xy.shape[1]
    n = m - 1
    sep2 = np.empty((rows, m, k))
    for a in range(rows):
        ha = hs[min(a, hs.shape[0] - 1)]
        for i in range(m):
            for q in range(k):
                rel = xy[a, i] - txy[lvl, i, ids[q]]
                rh = ha[i] - th[lvl, i, ids[q]]
                if aspect > 0:
                    rh = aspect * rh
                    sep2[a, i, q] = max(rel.real**2 + rel.imag**2, rh**2)
                else:
                    if scaled:  # no more than the chords on either side stretch it
                        j = ids[q]
                        rh = min(tv[lvl, i, j], tv[lvl, min(i + 1, n), j],
                                 tv[lvl, max(i - 1, 0), j]) * rh  # fmt: skip
                    sep2[a, i, q] = rel.real**2 + rel.imag**2 + rh**2
    slack = 0.5 * (own_step + step_max) + 1e-6
    if aspect > 0:
        slack = max(1.0, aspect) * (slack - 1e-6) + 1e-6
    elif scaled:
        slack = tvmax * (slack - 1e-6) + 1e-6
    lowest = np.inf
    for a in range(rows):
        for i in range(m):
            for q in range(k):
                if margined:
                    grow = max(tm[lvl, i, ids[q]], tm[lvl, min(i + 1, n), ids[q]])
                    lowest = min(lowest, math.sqrt(sep2[a, i, q]) - grow)
                else:
                    lowest = min(lowest, sep2[a, i, q])
    close = lowest < dmin + slack if margined else lowest < (dmin + slack) ** 2
    frac = np.empty((rows, n, k))
    if not close:
        return sep2, frac, False
    chords = np.empty((rows, n, k))
    for a in range(rows):
        ha = hs[min(a, hs.shape[0] - 1)]
        for i in range(n):
            for q in range(k):
                j = ids[q]
                r0 = xy[a, i] - txy[lvl, i, j]
                r1 = xy[a, i + 1] - txy[lvl, i + 1, j]
                h0, h1 = ha[i] - th[lvl, i, j], ha[i + 1] - th[lvl, i + 1, j]
                if aspect > 0:
                    d2, s = _cylinder_chord(r0.real, r0.imag, aspect * h0, r1.real, r1.imag,
                                            aspect * h1)  # fmt: skip
                elif scaled:
                    f = min(tv[lvl, i, j], tv[lvl, i + 1, j])
                    h0, h1 = f * h0, f * h1
                    d2, s = _chord(r0.real, r0.imag, h0, r1.real, r1.imag, h1,
                                   r0.real**2 + r0.imag**2 + h0**2)  # fmt: skip
                else:
                    d2, s = _chord(r0.real, r0.imag, h0, r1.real, r1.imag, h1, sep2[a, i, q])
                chords[a, i, q], frac[a, i, q] = d2, s
                need = dmin + tm[lvl, i + 1, j] if margined else dmin
                if k_hit[a] == n and d2 < need**2:
                    k_hit[a] = i
    return chords, frac, True


@njit(cache=True)
def _closest(sep2, frac, exact, tm, lvl, ids, k, k_event, dt, margined, a, out):
    """_closest_approach for row ``a``: (min_sep, closest id, t_closest) into ``out``."""
    last = k_event if exact else k_event + 1
    best, bi, bq = np.inf, 0, 0
    for i in range(min(last + 1, sep2.shape[1])):
        for q in range(k):
            if margined:
                m = tm[lvl, i + 1, ids[q]] if exact else tm[lvl, i, ids[q]]
                g = math.sqrt(sep2[a, i, q]) - m
            else:
                g = sep2[a, i, q]
            if g < best:
                best, bi, bq = g, i, q
    out[0] = max(best, 0.0) if margined else math.sqrt(best)
    out[1] = ids[bq]
    out[2] = (bi + frac[a, bi, bq]) * dt if exact else bi * dt


@njit(cache=True)
def _keeps_clear(sep2, frac, exact, tm, ts, lvl, ids, k, k_event, a, par, loss):
    """The chance that row ``a``'s edge keeps clear of the ``k`` intruders ``ids``, up to its
    event (risk as a probability: uavxai.avoidance.risk), each intruder independent."""
    last = k_event if exact else k_event + 1  # as _closest counts
    edge_loss(sep2[a], frac[a], exact, tm[lvl], ts[lvl], ids, k, last, lvl == 0, par[DMIN], loss)
    keeps = 1.0
    for q in range(k):
        keeps *= 1.0 - loss[q]
    return keeps


@njit(cache=True)
def _first_out(xy, hs, par):
    """Per row, the first sub-step whose end is out of the flight area (n: none)."""
    rows, n = xy.shape[0], xy.shape[1] - 1
    out = np.full(rows, n)
    for a in range(rows):
        ha = hs[min(a, hs.shape[0] - 1)]
        for i in range(1, n + 1):
            x, y, h = xy[a, i].real, xy[a, i].imag, ha[i]
            if x < par[XB0] or x > par[XB1] or y < par[YB0] or y > par[YB1] or h < par[HB0] or (
                h > par[HB1]
            ):
                out[a] = i - 1
                break
    return out


@njit(cache=True)
def _first_goal(xy, hs, par):
    """Per row, the first sub-step that passes within the tree's goal radius (n: none;
    PlannerConfig.goal_aim_m)."""
    rows, n = xy.shape[0], xy.shape[1] - 1
    out = np.full(rows, n)
    r2 = par[GOALR] ** 2
    for a in range(rows):
        ha = hs[min(a, hs.shape[0] - 1)]
        for i in range(n):
            x0, y0, h0 = xy[a, i].real - par[GX], xy[a, i].imag - par[GY], ha[i] - par[GH]
            x1, y1 = xy[a, i + 1].real - par[GX], xy[a, i + 1].imag - par[GY]
            h1 = ha[i + 1] - par[GH]
            d2, _ = _chord(x0, y0, h0, x1, y1, h1, x0**2 + y0**2 + h0**2)
            if d2 < r2:
                out[a] = i
                break
    return out


@njit(cache=True)
def _place(node, first, kk, state, depth, parent, action, bend, climbs, drift, par):
    """The K children of ``node`` (EncounterModel.expand's Children.state): states, keys,
    links. Returns origin, rot and the children's heights."""
    kn = climbs.size
    x, y, h, psi = state[node, 0], state[node, 1], state[node, 2], state[node, 4]
    origin = complex(x, y)
    rot = complex(math.cos(psi), -math.sin(psi))
    sink = par[CLIMB] * par[DUR]
    heights = np.empty(kn)
    h_ends = np.empty(kn)
    for a in range(kn):
        vcm = 0
        target = par[GH]
        if par[VERT] > 0:
            vcm = min(max(int(state[node, 7]) + climbs[a], -1), 1)
            target = par[TDOWN] if vcm < 0 else (par[TUP] if vcm > 0 else par[TLEVEL])
        heights[a] = target
        h_ends[a] = h + min(max(target - h, -sink), bend[kk, a, RISEEND])
        c = first + a
        p = (origin + drift[-1]) + complex(bend[kk, a, ZRE], bend[kk, a, ZIM]) * rot
        state[c, 0], state[c, 1], state[c, 2] = p.real, p.imag, h_ends[a]
        state[c, 3], state[c, 4] = bend[kk, a, VEND], (psi + bend[kk, a, DPSI]) % _TAU
        state[c, 5], state[c, 6], state[c, 7] = bend[kk, a, PHIEND], bend[kk, a, PHICMD], vcm
        depth[c], parent[c], action[c] = depth[node] + 1, node, a
    return origin, rot, heights, h_ends


@njit(cache=True)
def _box(h, origin, rot, kk, h_ends, bscal, drift):
    """The cylinder holding the children's paths: (x, y, h, horizontal radius, half-height)."""
    half = 0.5 * drift[-1]
    c = origin + complex(bscal[kk, BALLRE], bscal[kk, BALLIM]) * rot + half
    h_lo, h_hi = h, h
    for a in range(h_ends.size):
        h_lo, h_hi = min(h_lo, h_ends[a]), max(h_hi, h_ends[a])
    return (c.real, c.imag, 0.5 * (h_lo + h_hi), bscal[kk, BALLR] + abs(half),
            0.5 * (h_hi - h_lo), h_lo == h_hi)  # fmt: skip


@njit(cache=True)
def _walls(box, par):
    """_near_wall: could a path inside ``box`` leave the flight area?"""
    x, y, h, r_xy, r_h = box[0], box[1], box[2], box[3], box[4]
    inside_x = par[XB0] <= x - r_xy and x + r_xy <= par[XB1]
    inside_y = par[YB0] <= y - r_xy and y + r_xy <= par[YB1]
    return not (inside_x and inside_y and par[HB0] <= h - r_h and h + r_h <= par[HB1])


@njit(cache=True)
def _goal_near(box, par):
    """_near_goal: could a path inside ``box`` come within the tree's goal radius?"""
    d = math.sqrt((box[0] - par[GX]) ** 2 + (box[1] - par[GY]) ** 2 + (box[2] - par[GH]) ** 2)
    return d <= math.hypot(box[3], box[4]) + par[GOALR]


@njit(cache=True)
def _samples(h, origin, rot, kk, heights, level, bz, brise, drift, par):
    """Sub-step positions of the K children: (K, n+1) complex, (1 or K, n+1) heights."""
    kn, m = bz.shape[1], bz.shape[2]
    xy = np.empty((kn, m), dtype=np.complex128)
    for a in range(kn):
        for i in range(m):
            xy[a, i] = origin + bz[kk, a, i] * rot + drift[i]
    if level:
        return xy, np.full((1, m), h)
    hs = np.empty((kn, m))
    step = -par[CLIMB] * (par[DUR] / (m - 1))
    for a in range(kn):
        for i in range(m):
            hs[a, i] = h + min(max(heights[a] - h, step * i), brise[kk, a, i])
    return xy, hs


@njit(cache=True)
def _end_value(cd, clear_c, t, depth_limit, par):
    """The value of a child whose line ends (nan while it is open): the goal, what its NMAC
    intrusion leaves of it (graded separation: arriving through an NMAC is worth less); a
    time-out a tenth of that; a collision at ``t`` s ``late_collision_value`` times the
    horizon's share gone; leaving the area 0."""
    if cd == _NONE:
        return np.nan
    if cd == _GOAL:
        return clear_c
    if cd == _TIMEOUT:
        return 0.1 * clear_c
    if cd == _COLLISION and par[LATE] > 0:
        return par[LATE] * t / (depth_limit * par[DUR])
    return 0.0


@njit(cache=True)
def _expand(node, tree, bz, brise, bend, bscal, child, tracks, climbs, drift, par, near):
    """TreeBuilder.expand over EncounterModel.expand: the K children of ``node``, appended
    to the tree; returns the first child's index."""
    (visits, value_sum, best, first_child, is_leaf, value, key, state, depth, parent, action,
     code, min_sep, closest, t_closest, surv, clear, count, depth_limit) = tree  # fmt: skip
    txy, th, tm, tmargined, tstep, tc, tr, ts, tv, tvmax = tracks
    kn, n = climbs.size, bz.shape[2] - 1
    first = count[0]
    count[0] += kn
    first_child[node] = first
    kk = key[node]
    lvl = depth[node]
    origin, rot, heights, h_ends = _place(node, first, kk, state, depth, parent, action, bend,
                                          climbs, drift, par)  # fmt: skip
    h = state[node, 2]
    box = _box(h, origin, rot, kk, h_ends, bscal, drift)
    k = _near(tc, tr, lvl, box[0], box[1], box[2], math.hypot(box[3], box[4]) + par[CULL], near)
    walls, goal = _walls(box, par), _goal_near(box, par)
    dt = par[DUR] / n
    k_event = np.full(kn, n)
    kind = np.zeros(kn, dtype=np.int8)
    res = np.empty(3)
    risky = par[RISK] > 0
    edge_surv = np.ones(kn)  # per child, the chance its edge keeps clear of every track
    edge_clear = np.ones(kn)  # per child, what its edge's NMAC intrusion leaves (nmac_cost)
    loss = np.empty(max(k, 1))
    if k or walls or goal:
        xy, hs = _samples(h, origin, rot, kk, heights, box[5], bz, brise, drift, par)
        k_hit = np.full(kn, n)
        if k:
            sep2, frac, exact = _hits(xy, hs, txy, th, tm, lvl, near, k, bscal[kk, OWNSTEP],
                                      tstep[lvl], tmargined[lvl], par[DMIN], par[ASPECT],
                                      k_hit, tv, tvmax[lvl], par[VSCALED] > 0)  # fmt: skip
        k_out = _first_out(xy, hs, par) if walls else np.full(kn, n)
        k_goal = _first_goal(xy, hs, par) if goal else np.full(kn, n)
        for a in range(kn):  # the first event wins; collision, then the walls, then the goal
            k_event[a], kind[a] = k_hit[a], _COLLISION
            if k_out[a] < k_event[a]:
                k_event[a], kind[a] = k_out[a], _OUT
            if k_goal[a] < k_event[a]:
                k_event[a], kind[a] = k_goal[a], _GOAL
            if k:
                _closest(sep2, frac, exact, tm, lvl, near, k, k_event[a], dt, tmargined[lvl], a,
                         res)  # fmt: skip
                min_sep[first + a], closest[first + a] = res[0], int(res[1])
                t_closest[first + a] = res[2]
                if par[NMACW] > 0:  # the edge up to its event, as _closest measures it
                    edge_clear[a] = _nmac_factor(xy, hs, txy, th, tm, tmargined[lvl], lvl,
                                                 near, k, a, k_event[a] + 1, par)  # fmt: skip
                if risky:
                    edge_surv[a] = _keeps_clear(sep2, frac, exact, tm, ts, lvl, near, k,
                                                k_event[a], a, par, loss)  # fmt: skip
    for a in range(kn):
        c = first + a
        if not k:
            min_sep[c], closest[c], t_closest[c] = np.inf, -1, 0.0
        clear[c] = min(clear[node], edge_clear[a])  # the line's deepest intrusion counts
        happened = k_event[a] < n
        cd = kind[a] if happened else _NONE
        if cd == _NONE and (lvl + 1) * par[DUR] >= par[TLEFT] - 1e-9:
            cd = _TIMEOUT
        code[c] = cd
        visits[c], value_sum[c], best[c], first_child[c] = 0, 0.0, -np.inf, -1
        is_leaf[c] = lvl + 1 == depth_limit or cd != _NONE
        value[c] = _end_value(cd, clear[c], lvl * par[DUR] + k_event[a] * dt, depth_limit, par)
        if cd == _COLLISION and par[WALLT] > 0:
            # A late collision is a meeting re-planning may still turn into a miss, if the
            # ownship is still in the area to re-plan: weigh it by the walls at its edge's end
            # as an open leaf is (issue 31: when a swollen margin makes every line collide,
            # late meetings that ignore the walls lead out of the area).
            value[c] *= wall_factor(state[c], par)
        if risky:  # the line so far keeps clear with this chance: its value's weight
            surv[c] = surv[node] * edge_surv[a]
            if cd == _COLLISION:  # a hard collision keeps its (late) value, weighed by
                value[c] *= surv[node]  # the chance of getting that far
            elif cd != _NONE:
                value[c] *= surv[c]
        key[c] = child[kk, a]
    return first


@njit(cache=True)
def nmac_depth(hd, vd, par):
    """How deep a point ``hd`` m horizontally and ``vd`` m vertically from a track's predicted
    position lies in its NMAC cylinder (``nmac_m``), in
    [0, 1]: 0 on or outside the rim, rising as the cylinder's norm ``max(hd / H, |vd| / V)``
    falls, 1 at the collision distance's share ``d_min / H`` of it and within."""
    norm = max(hd / par[NMACH], abs(vd) / par[NMACV])
    if norm >= 1.0:
        return 0.0
    return min((1.0 - norm) / (1.0 - par[DMIN] / par[NMACH]), 1.0)


@njit(cache=True)
def _nmac_factor(xy, hs, txy, th, tm, margined, lvl, ids, k, a, last, par):
    """What row ``a``'s edge keeps of its line's value (``nmac_cost``) for its deepest NMAC
    intrusion up to sub-step ``last``: ``1 - nmac_cost x depth`` (:func:`nmac_depth`), the
    horizontal miss less the track's margin (``tm``; the cylinder's height is not grown: the
    vertical escape stays cheap). The conflict at d_min stays the hard one: a collision's value
    is never weighed by this."""
    ha = hs[min(a, hs.shape[0] - 1)]
    deepest = 0.0
    for i in range(min(last + 1, xy.shape[1])):
        for q in range(k):
            rel = xy[a, i] - txy[lvl, i, ids[q]]
            hd = abs(rel) - tm[lvl, i, ids[q]] if margined else abs(rel)
            d = nmac_depth(max(hd, 0.0), ha[i] - th[lvl, i, ids[q]], par)
            deepest = max(deepest, d)
    return 1.0 - par[NMACW] * deepest


@njit(cache=True)
def wall_factor(row, par):
    """What a leaf (or a late collision, by its edge's end) keeps of its value for the walls
    it may not be able to turn away from (``wall_slack_s``): for each wall it heads towards
    (cosine ``c`` between its heading and the wall's outward normal), a turn away at the
    bank limit (radius ``R``, after rolling in) reaches ``R (1 - sqrt(1 - c^2)) + v t_roll c``
    closer; the slack left over that, in seconds of closing at ``v c``, over
    ``wall_slack_s``, clipped to [0, 1] (0: it can no longer turn away: as good as out).
    Headings clockwise from north."""
    x, y, v, psi = row[0], row[1], max(row[3], 1e-3), row[4]
    r = v * v / par[TURNG]
    ux, uy = math.sin(psi), math.cos(psi)
    f = 1.0
    for dist, c in ((x - par[XB0], -ux), (par[XB1] - x, ux), (y - par[YB0], -uy),
                    (par[YB1] - y, uy)):  # fmt: skip
        if c <= 0.0:
            continue
        need = r * (1.0 - math.sqrt(max(1.0 - c * c, 0.0))) + v * par[ROLLT] * c
        f *= min(max((dist - need) / (v * c) / par[WALLT], 0.0), 1.0)
    return f


@njit(cache=True)
def pinned_factor(row, lvl, tracks, drift, par):
    """What an open leaf (model state ``row`` at the end of tree level ``lvl``) keeps of its
    value for the tracks it is pinned by (``pinned_slack_s``, the vertical action set only):
    the product of :func:`pin_share` over the tracks."""
    f = 1.0
    for q in range(tracks[0].shape[2]):
        f *= pin_share(row, lvl, q, tracks, drift, par)
    return f


@njit(cache=True)
def pin_share(row, lvl, q, tracks, drift, par):
    """What track ``q`` leaves of a leaf's value (1: it does not pin the leaf). It pins it
    when the ownship is below it with less room from the track down to the floor's level-off
    than the track's conflict volume's half-height (``d_min`` plus its margin, over the
    spheroid's stretch or the cylinder's aspect), or above it with too little room up to the
    ceiling's: the ownship can let that track by only sideways. Then the share is the seconds
    before the track could close the horizontal gap left to its volume, both at their speeds
    head-on (the ownship's airspeed against the track's velocity in the air mass, ``drift``
    the wind's carry), over ``pinned_slack_s``, clipped to [0, 1]. The half-height is the one
    :func:`_hits` tests the leaf's last chord with (the spheroid's stretch the smaller of the
    chord's two ends')."""
    txy, th, tm, tmargined, tv = tracks[0], tracks[1], tracks[2], tracks[3], tracks[8]
    n = txy.shape[1] - 1
    tq = th[lvl, n, q]
    room = tq - par[TDOWN] if row[2] < tq else par[TUP] - tq
    base = par[DMIN] + (tm[lvl, n, q] if tmargined[lvl] else 0.0)
    if par[ASPECT] > 0:
        half = base / par[ASPECT]
    elif par[VSCALED] > 0:
        half = base / min(tv[lvl, n, q], tv[lvl, n - 1, q])
    else:
        half = base
    if room >= half:
        return 1.0
    p = txy[lvl, n, q]
    gap = math.hypot(row[0] - p.real, row[1] - p.imag) - base
    dt = par[DUR] / n
    closing = max(max(row[3], 0.0) + abs(p - txy[lvl, n - 1, q] - (drift[n] - drift[n - 1])) / dt,
                  1e-3)  # fmt: skip
    return min(max(gap / closing / par[PINT], 0.0), 1.0)


@njit(cache=True)
def _pin_shares(rows, lvls, tracks, drift, par):
    """(R, count): :func:`pin_share` of every track for each of ``rows`` at its level."""
    count = tracks[0].shape[2]
    out = np.ones((rows.shape[0], count))
    for r in range(rows.shape[0]):
        for q in range(count):
            out[r, q] = pin_share(rows[r], lvls[r], q, tracks, drift, par)
    return out


def pinned_by(
    model: EncounterModel, rows: np.ndarray, levels: np.ndarray, tracks: Sequence[Track]
) -> list[tuple[tuple[int, float], ...]]:
    """For each line's open end (model state ``rows[r]`` at the end of tree level
    ``levels[r]``), the tracks that pin it, as (index into the intruders, share of the
    line's value it leaves), the tightest first (:func:`pin_share`); all () when the planner
    does not weigh pinning. One compiled call for all of a decision's lines."""
    cfg = model.config
    rows = np.atleast_2d(np.asarray(rows, dtype=float))
    if cfg.pinned_slack_s <= 0 or not model.vertical or not tracks or not tracks[0].count:
        return [()] * len(rows)
    hold = cfg.action_hold_s
    n = model.substeps(hold)
    par = _params(model, np.zeros(3), hold, math.inf, tracks)
    shares = _pin_shares(rows, np.asarray(levels, dtype=np.int64), _pack(tracks, n),
                         model.drift(hold, n), par)  # fmt: skip
    return [
        tuple(sorted(((q, float(x)) for q, x in enumerate(row) if x < 1.0), key=lambda p: p[1]))
        for row in shares
    ]


def wall_share(model: EncounterModel, row: np.ndarray) -> float:
    """:func:`wall_factor` of a model state row outside a search (1 without ``wall_slack_s``):
    0 where the ownship can no longer turn away from a wall."""
    if model.config.wall_slack_s <= 0:
        return 1.0
    par = _params(model, np.zeros(3), model.config.action_hold_s, math.inf, [])
    return float(wall_factor(np.asarray(row, dtype=float), par))


@njit(cache=True)
def _pick(node, first, kn, visits, value_sum, best_value, by_best, explore, inv_sqrt, draw):
    """The UCT choice at ``node``: children never visited first, else the best score with
    Q (the mean of a child's walks, or with ``by_best`` the best value found below it)
    min-max normalised over the siblings; ties broken by ``draw``. The child's index in its
    block."""
    n = visits[node]
    best = np.empty(kn, dtype=np.int64)
    cnt = 0
    if n == 0:  # a fresh node: every child unvisited
        for j in range(kn):
            best[cnt] = j
            cnt += 1
    else:
        for j in range(kn):  # children never visited come first
            if visits[first + j] == 0:
                best[cnt] = j
                cnt += 1
        if cnt == 0:
            q = np.empty(kn)
            for j in range(kn):
                if by_best:
                    q[j] = best_value[first + j]
                else:
                    q[j] = value_sum[first + j] / visits[first + j]
            lo, hi = q.min(), q.max()
            # Q normalised over the siblings (as mctx does): leaf values 1 - d/d_max of
            # neighbouring actions differ by ~1 %, which the exploration term would swamp.
            scale = 1.0 / (hi - lo) if hi - lo > 1e-12 else 0.0
            e = explore[n]
            scores = np.empty(kn)
            for j in range(kn):
                scores[j] = (q[j] - lo) * scale + e * inv_sqrt[visits[first + j]]
            top = scores.max()
            for j in range(kn):
                if scores[j] == top:
                    best[cnt] = j
                    cnt += 1
    return best[0] if cnt == 1 else best[int(draw * cnt)]


@njit(cache=True)
def run(tree, bz, brise, bend, bscal, child, tracks, climbs, drift, par, explore, inv_sqrt,
        draws, simulations):  # fmt: skip
    """``simulations`` MCTS simulations from the root (node 0) of ``tree`` (the algorithm:
    the docstring of uavxai.avoidance.mcts). Returns the number of nodes."""
    (visits, value_sum, best, first_child, is_leaf, value, key, state, depth, parent, action,
     code, min_sep, closest, t_closest, surv, clear, count, depth_limit) = tree  # fmt: skip
    kn = climbs.size
    near = np.empty(tracks[5].shape[1], dtype=np.int64)
    path = np.zeros(depth_limit + 1, dtype=np.int64)
    draw = 0
    by_best = par[BEST] > 0
    for _ in range(simulations):
        node, length = 0, 1
        while not is_leaf[node]:
            first = first_child[node]
            if first < 0:
                first = _expand(node, tree, bz, brise, bend, bscal, child, tracks, climbs, drift,
                                par, near)  # fmt: skip
            pick = _pick(node, first, kn, visits, value_sum, best, by_best, explore, inv_sqrt,
                         draws[draw])  # fmt: skip
            draw += 1
            node = first + pick
            path[length] = node
            length += 1
        v = value[node]
        if v != v:  # nan: an open leaf at the depth limit, scored when first reached
            # goal_height_scale: a metre of height off the goal's counts as that many (1: the
            # paper's 3-D distance). Counted so, a leaf may lie farther than the area's
            # diagonal: its value stops at 0, or the factors below (at most 1: NMAC intrusion,
            # walls, risk) would reward what they cost. At 1 it never does (d <= d_max).
            d = math.sqrt((state[node, 0] - par[GX]) ** 2 + (state[node, 1] - par[GY]) ** 2
                          + (par[HSCALE] * (state[node, 2] - par[GH])) ** 2)  # fmt: skip
            v = max(1.0 - d / par[DMAX], 0.0) * clear[node]
            if par[WALLT] > 0:
                v *= wall_factor(state[node], par)
            if par[PINT] > 0:
                v *= pinned_factor(state[node], depth[node] - 1, tracks, drift, par)
            if par[RISK] > 0:
                v *= surv[node]
            value[node] = v
        if by_best and code[node] == _GOAL:  # sooner is better, as the exhaustive search has it
            v -= par[GDELAY] * (depth[node] - 1)
        for k in range(length):
            p = path[k]
            visits[p] += 1
            value_sum[p] += v
            best[p] = max(best[p], v)
    return count[0]


def search(
    model: EncounterModel,
    root: np.ndarray,
    goal: np.ndarray,
    tracks: Sequence[Track],
    *,
    simulations: int,
    c: float,
    hold_s: float,
    rng: np.random.Generator,
    time_left_s: float = math.inf,
    scratch: dict | None = None,
) -> SearchTree:
    """Run MCTS from ``root`` (a model state row) and return the tree (the algorithm: the
    docstring of :mod:`uavxai.avoidance.mcts`).

    ``scratch``: a dict the caller keeps from one search to the next, where the kernel's tree
    arrays are kept and reused (allocating and filling them cost more than a third of the
    compiled search); the returned tree is a copy, never a view of them.

    ``tracks[d]`` holds the intruders during tree level ``d``, i.e. over
    ``[d * hold_s, (d + 1) * hold_s]`` from now; the search depth is ``len(tracks)``.
    ``time_left_s`` is when the episode times out: nodes reached later are time-outs.
    Node 0 is the root; the children of a node are K consecutive nodes in action order (K the
    action set's size, ``model.actions``), as :class:`uavxai.avoidance.mcts.TreeBuilder`
    gives them.
    """
    depth_limit = len(tracks)
    explore, inv_sqrt = _uct_tables(simulations, c)
    draws = rng.random(simulations * depth_limit)  # tie-breaks, one per step, as in Python
    keys, child = model.motions(np.asarray(root, dtype=float).tolist(), hold_s, depth_limit)
    bodies = [model.motion(key) for key in keys]
    n = model.substeps(hold_s)
    bend = np.stack([b.table for b in bodies])
    bscal = np.array(
        [(b.ball.real, b.ball.imag, b.ball_r, model._own_step(b, hold_s / n)) for b in bodies]
    )
    bz = np.stack([b.z for b in bodies])
    brise = np.stack([b.rise for b in bodies])
    tree = _empty_tree(model, root, simulations, depth_limit, {} if scratch is None else scratch)
    size = run(tree, bz, brise, bend, bscal, child, _pack(tracks, n), model.climbs,
               model.drift(hold_s, n), _params(model, goal, hold_s, time_left_s, tracks), explore,
               inv_sqrt, draws, simulations)  # fmt: skip
    return _as_search_tree(tree, int(size), model.actions.size, hold_s, time_left_s,
                           _risky(model, tracks), model.config.backup == "best",
                           model.config.nmac_cost)  # fmt: skip


def goal_delay(config: PlannerConfig, depth: int) -> float:
    """What reaching the goal one tree level later costs a line (the tree planners' tie-break:
    sooner is better; the exhaustive search's, and MCTS's with ``backup: best``). Every line
    that reaches the goal within the horizon scores 1, so without it a planner may take a line
    that reaches it only at the horizon, and re-planning then puts the goal off forever (the
    exhaustive search orbited the goal in 0.5-2.5 % of campaign episodes). Kept below the gap
    between the goal and any other leaf (1 - d/d_max with d >= the radius the tree counts the
    goal within, PlannerConfig.goal_aim_m), so only ties change."""
    return min(GOAL_DELAY, 0.5 * config.goal_aim_m / config.d_max / max(depth, 1))


@functools.lru_cache(maxsize=8)
def _uct_tables(simulations: int, c: float) -> tuple[np.ndarray, np.ndarray]:
    """UCT's ``2C sqrt(2 ln n)`` and ``1 / sqrt(n_j)`` by visit count: the score is
    ``Q + [2C sqrt(2 ln n)] * [1 / sqrt(n_j)]``, both from tables."""
    explore = np.array(
        [2.0 * c * math.sqrt(2.0 * math.log(n)) if n else 0.0 for n in range(simulations)]
    )
    inv_sqrt = np.array([1.0 / math.sqrt(n) if n else math.inf for n in range(simulations)])
    explore.flags.writeable = inv_sqrt.flags.writeable = False
    return explore, inv_sqrt


def _pack(tracks: Sequence[Track], n: int) -> tuple:
    """The intruders' tracks per tree level, as arrays."""
    count = tracks[0].count
    vscale = np.stack([np.ones((n + 1, count)) if t.vscale is None else t.vscale
                       for t in tracks])  # fmt: skip
    margin = np.stack([np.zeros((n + 1, count)) if t.margin is None else t.margin
                       for t in tracks])  # fmt: skip
    return (
        np.stack([t.xy for t in tracks]),
        np.stack([t.h for t in tracks]),
        margin,
        np.array([t.margin is not None for t in tracks]),
        np.array([t.step_max for t in tracks]),
        np.stack([t.centre for t in tracks]).reshape(len(tracks), count, 3),
        np.stack([t.radius for t in tracks]).reshape(len(tracks), count),
        np.stack([np.zeros((n + 1, count)) if t.sigma is None else t.sigma
                  for t in tracks]),  # fmt: skip
        vscale,
        vscale.reshape(len(tracks), -1).max(axis=1, initial=1.0),
    )


def _risky(model: EncounterModel, tracks: Sequence[Track]) -> bool:
    """Does the search weigh its lines by their chance of keeping clear: risk as a
    probability, and some track error to weigh (none: the values are the margin's)."""
    return model.config.risk == "probability" and any(t.sigma is not None for t in tracks)


def _params(
    model: EncounterModel,
    goal: np.ndarray,
    hold_s: float,
    time_left_s: float,
    tracks: Sequence[Track],
):
    cfg = model.config
    gh = float(goal[2])
    nmac_r = math.hypot(*cfg.nmac_m)  # the sphere holding the NMAC cylinder
    return np.array(
        [cfg.d_min_m, cfg.goal_aim_m, *cfg.x_bounds, *cfg.y_bounds, *cfg.h_bounds,
         cfg.climb_rate_mps, hold_s, time_left_s, cfg.late_collision_value, cfg.d_max,
         float(model.vertical), cfg.height_target(-1, gh), cfg.height_target(0, gh),
         cfg.height_target(1, gh), float(goal[0]), float(goal[1]), gh,
         max(cfg.cull_m, nmac_r) if cfg.nmac_cost > 0 else cfg.cull_m,
         cfg.cylinder_aspect or 0.0, float(_risky(model, tracks)), cfg.nmac_cost, *cfg.nmac_m,
         cfg.wall_slack_s, G * math.tan(cfg.bank_limit_rad),
         cfg.bank_limit_deg / cfg.roll_rate_limit_deg_s, float(cfg.backup == "best"),
         goal_delay(cfg, len(tracks)),
         float(any(t.vscale is not None for t in tracks)), cfg.goal_height_scale,
         cfg.pinned_slack_s if model.vertical else 0.0],  # fmt: skip
        dtype=float,
    )


def _empty_tree(
    model: EncounterModel, root: np.ndarray, simulations: int, depth_limit: int, scratch: dict
):
    """The kernel's tree arrays, sized for the most nodes the search can make, root filled:
    ``scratch``'s from an earlier search of the same size if it has them (every node but the
    root is written whole when the kernel expands it, so only the root is filled again)."""
    k = model.actions.size
    cap = 1 + k * (1 + simulations * max(depth_limit - 1, 0))
    tree = scratch.get((cap, depth_limit))
    if tree is None:
        tree = scratch[(cap, depth_limit)] = (
            np.zeros(cap, dtype=np.int64),  # visits
            np.zeros(cap),  # value_sum
            np.full(cap, -np.inf),  # best: the best value a walk through the node has scored
            np.full(cap, -1, dtype=np.int64),  # first_child
            np.zeros(cap, dtype=np.bool_),  # is_leaf
            np.full(cap, np.nan),  # value
            np.zeros(cap, dtype=np.int64),  # key
            np.zeros((cap, 8)),  # state
            np.zeros(cap, dtype=np.int64),  # depth
            np.full(cap, -1, dtype=np.int64),  # parent
            np.full(cap, -1, dtype=np.int64),  # action
            np.zeros(cap, dtype=np.int8),  # code
            np.full(cap, np.inf),  # min_sep
            np.full(cap, -1, dtype=np.int64),  # closest
            np.full(cap, np.nan),  # t_closest
            np.ones(cap),  # surv: the chance the line to the node keeps clear (risk "probability")
            np.ones(cap),  # clear: what the line's NMAC intrusions leave of its value (nmac_cost)
            np.ones(1, dtype=np.int64),  # count
            depth_limit,
        )
    (visits, value_sum, best, first_child, is_leaf, value, key, state, depth, parent, action,
     code, min_sep, closest, t_closest, surv, clear, count, _) = tree  # fmt: skip
    visits[0], value_sum[0], first_child[0], is_leaf[0], value[0], key[0] = 0, 0.0, -1, 0, np.nan, 0
    best[0] = -np.inf
    state[0] = np.asarray(root, dtype=float)[:8]
    depth[0], parent[0], action[0], code[0] = 0, -1, -1, 0
    min_sep[0], closest[0], t_closest[0], surv[0], count[0] = np.inf, -1, np.nan, 1.0, 1
    clear[0] = 1.0
    return tree


def _as_search_tree(
    tree,
    size: int,
    k: int,
    hold_s: float,
    time_left_s: float,
    risky: bool,
    by_best: bool,
    nmac_cost: float,
) -> SearchTree:
    (visits, value_sum, best, first_child, _, _, _, state, depth, parent, action, code,
     min_sep, closest, t_closest, surv, clear, _, _) = tree  # fmt: skip
    d = depth[:size].copy()
    states = state[:size].copy()
    n = visits[:size].copy()
    # with the best-value backup value_sum holds best x visits (what sums values keeps working)
    # and SearchTree.best the best value found below a node itself, which Q reads, as in the
    # exhaustive search's tree
    total = np.where(n > 0, best[:size], 0.0) * n if by_best else value_sum[:size].copy()
    return SearchTree(
        parent=parent[:size].copy(),
        action=action[:size].copy(),
        depth=d,
        visits=n,
        value_sum=total,
        min_sep=min_sep[:size].copy(),
        closest=closest[:size].copy(),
        terminal=code[:size].copy(),
        pos=states[:, :3].copy(),
        t_closest=t_closest[:size] + np.maximum(d - 1, 0) * hold_s,
        state=states,
        first_child=first_child[:size].copy(),
        branching=k,
        time_left_s=time_left_s,
        risk=1.0 - surv[:size] if risky else None,
        by_value=by_best,
        # clear = 1 - nmac_cost x depth (_nmac_factor): the depth it was graded by
        nmac_depth=(1.0 - clear[:size]) / nmac_cost if nmac_cost > 0 else None,
        best=best[:size].copy() if by_best else None,
    )
