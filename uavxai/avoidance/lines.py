"""What a planner's lines predict, in the terms an explanation quotes them.

A tree search decides on separations net of the intruders' margins (what they could do, how
uncertain their tracks are: :func:`uavxai.avoidance.model.intruder_margin`) and stops a line
at its first conflict. Words need other numbers: how close the line passes each intruder on
its predicted track (a distance flight can be compared with), and for a conflict the
*predicted miss* (the closest approach, the line's last action held to the end of its level)
beside the separation that was needed. :func:`measure_line` computes them from the line's
sampled positions and the intruders' tracks; :func:`flies` says which manoeuvre an action
really is once its commands are clamped; :func:`cornered_choice` is the rule a tree planner
chooses by when every option conflicts.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from uavxai.avoidance.model import (
    COLLISION,
    GOAL,
    NONE,
    OUT_OF_BOUNDS,
    Track,
    bank_command,
    vertical_command,
)
from uavxai.avoidance.risk import edge_loss
from uavxai.avoidance.types import ChildStats, Meeting, Ownship, PlannerConfig, SearchTree
from uavxai.geometry import closest_on_pieces, closest_on_pieces_cylinder
from uavxai.vocabulary import ACTIONS, Outcome

# A speed change smaller than this share of what the action commands over one tree level
# (accel_mps2 x action_hold_s) is no change: at the speed limit "faster" flies as "same".
SPEED_CHANGE_SHARE = 0.1


@dataclass(frozen=True)
class LineMeasure:
    """Predicted separations along one line (see the module docstring)."""

    min_sep_m: float  # closest approach to any intruder on its predicted track (inf: none)
    closest: int  # index of that intruder (-1: none)
    t_closest_s: float | None  # when, from the decision
    meets: tuple[int, float, float, float] | None  # (intruder index, time, miss, needed)
    horizon_s: float  # how far ahead the line reaches
    # Other intruders whose track error (their margin at their closest approach) could bring
    # them closer than ``closest`` on its predicted track: (index, closest approach less that
    # margin, m), the least first. The prediction is not sure which intruder passes closest.
    unsure: tuple[tuple[int, float], ...] = ()
    # With risk as a probability (tracks with ``sigma``): the chance that the line loses
    # separation with each intruder (index, chance), the likeliest first, those above 0 only,
    # and with any of them (None: risk not weighed).
    losses: tuple[tuple[int, float], ...] = ()
    risk: float | None = None


def measure_line(
    samples: Sequence[np.ndarray],
    levels: Sequence[int],
    ends: Sequence[tuple[int, float]],
    tracks: Sequence[Track],
    hold_s: float,
    d_min_m: float,
    chords: Sequence[tuple[np.ndarray, np.ndarray]] | None = None,
    aspect: float | None = None,
) -> LineMeasure:
    """Measure a line of edges: ``samples[e]`` (n+1, 3) ownship positions at the sub-step
    instants of edge ``e``, flown at tree level ``levels[e]`` against ``tracks[level]``;
    ``ends[e]`` its (terminal code, time of the event's sub-step within the edge).

    Within a sub-step both aircraft move on straight lines, so the closest approach of each
    is solved exactly. A line that reaches the goal or leaves the area counts up to the end of
    that event's sub-step (it stops there); one that collides is measured to the end of the
    edge, so that its miss is the closest approach, not where it first came too close.
    ``chords[e]``: edge ``e``'s :func:`chord_distances`, if computed already.
    ``aspect``: separations in the conflict cylinder's norm (``PlannerConfig.cylinder_aspect``;
    None: 3-D distances, the sphere's). Many lines at once: :func:`measure_lines`.
    """
    used = _used(ends)
    n_int = tracks[0].count if tracks else 0
    n = samples[0].shape[0] - 1
    if not n_int:
        empty = np.zeros((1, used, n, 0))
        return measure_lines(empty, empty, [levels], [ends], tracks, hold_s, d_min_m)[0]
    if chords is None:
        chords = [chord_distances(samples[e], tracks[levels[e]].pos, aspect)
                  for e in range(used)]  # fmt: skip
    dist = np.stack([chords[e][0] for e in range(used)])[None]  # (1, E, n, N)
    frac = np.stack([chords[e][1] for e in range(used)])[None]
    return measure_lines(dist, frac, [levels], [ends], tracks, hold_s, d_min_m)[0]


def _used(ends: Sequence[tuple[int, float]]) -> int:
    """How many edges of a line count: up to its first terminal one."""
    return next((e + 1 for e, (code, _) in enumerate(ends) if code != NONE), len(ends))


def measure_lines(
    dist: np.ndarray,
    frac: np.ndarray,
    levels: Sequence[Sequence[int]],
    ends: Sequence[Sequence[tuple[int, float]]],
    tracks: Sequence[Track],
    hold_s: float,
    d_min_m: float,
) -> list[LineMeasure]:
    """:func:`measure_line` of L lines in one vectorised pass (a tree planner quotes one line
    per root action; measured one by one, their small arrays cost more than the search):
    ``dist``, ``frac`` (L, U, n, N) the :func:`chord_distances` of line ``l``'s edge ``e``
    (edges beyond a line's own, up to U, are padding and never read); ``levels[l]``,
    ``ends[l]`` as :func:`measure_line` has them. Every number is computed per line as that
    function says, so a line measures the same alone or in a batch."""
    n_lines, width, n, n_int = dist.shape
    dt = hold_s / n
    keep = np.zeros((n_lines, width), dtype=int)  # sub-steps counted per edge (0: padding)
    lev = np.zeros((n_lines, width), dtype=int)
    used_of = [_used(line_ends) for line_ends in ends]
    for ln, used in enumerate(used_of):
        keep[ln, :used] = n
        code, t_event = ends[ln][used - 1]
        if code in (GOAL, OUT_OF_BOUNDS) and math.isfinite(t_event):
            keep[ln, used - 1] = min(n, int(round(t_event / dt)) + 1)
        lev[ln, :used] = levels[ln][:used]
    t0 = lev.astype(float) * hold_s
    rows, last = np.arange(n_lines), np.array(used_of) - 1
    horizons = (t0[rows, last] + keep[rows, last] * dt).tolist()
    if not n_int:
        return [LineMeasure(math.inf, -1, None, None, h) for h in horizons]
    # the closest approach to each intruder over the kept sub-steps, the first if tied
    kept = np.where(np.arange(n)[None, None, :, None] < keep[:, :, None, None], dist, np.inf)
    first = kept.reshape(n_lines, width * n, n_int).argmin(axis=1)  # (L, N)
    e, k = np.divmod(first, n)
    rows, cols = rows[:, None], np.arange(n_int)[None, :]
    best = kept[rows, e, k, cols]
    best_t = t0[rows, e] + (k + frac[rows, e, k, cols]) * dt
    margins = np.stack([np.zeros((n + 1, n_int)) if t.margin is None else t.margin
                        for t in tracks])  # fmt: skip
    best_margin = margins[lev[rows, e], k + 1, cols]  # the sub-step's end margin, as held
    could = np.maximum(best - best_margin, 0.0)
    # per line: the closest intruder j, and the others whose margin could bring them closer
    # (the least first)
    j = np.argmin(best, axis=1)
    order = np.argsort(could, axis=1, kind="stable")
    sorted_could = np.take_along_axis(could, order, axis=1)
    unsure = (order != j[:, None]) & (sorted_could < best[rows[:, 0], j][:, None])
    found = np.isfinite(best).any(axis=1).tolist()
    best_j, t_j = best[rows[:, 0], j].tolist(), best_t[rows[:, 0], j].tolist()
    out = []
    for ln, used in enumerate(used_of):
        if not found[ln]:
            out.append(LineMeasure(math.inf, -1, None, None, horizons[ln]))
            continue
        met = None
        if ends[ln][used - 1][0] == COLLISION:
            who, when, needed = _first_conflict(
                dist[ln, used - 1], tracks[levels[ln][used - 1]], d_min_m,
                float(t0[ln, used - 1]), dt,
            )  # fmt: skip
            met = (who, when, float(best[ln, who]), needed)
        pick = unsure[ln]
        doubt = tuple(zip(order[ln][pick].tolist(), sorted_could[ln][pick].tolist(), strict=True))
        losses, risk = _line_losses(dist[ln, :used], frac[ln, :used], keep[ln, :used],
                                    levels[ln][:used], tracks, d_min_m)  # fmt: skip
        out.append(LineMeasure(best_j[ln], int(j[ln]), t_j[ln], met, horizons[ln], doubt,
                               losses, risk))  # fmt: skip
    return out


def _line_losses(
    dist: np.ndarray,
    frac: np.ndarray,
    keep: np.ndarray,
    levels: Sequence[int],
    tracks: Sequence[Track],
    d_min_m: float,
) -> tuple[tuple[tuple[int, float], ...], float | None]:
    """:attr:`LineMeasure.losses` and ``risk`` of a line whose edges' chords are ``dist``,
    ``frac`` (E, n, N), edge ``e`` counted over its first ``keep[e]`` sub-steps: per edge the
    search's own :func:`edge_loss`, combined over edges and intruders as independent."""
    if any(tracks[lv].sigma is None for lv in levels):
        return (), None
    n_int = dist.shape[2]
    ids = np.arange(n_int)
    keeps = np.ones(n_int)  # per intruder, the chance the line keeps clear of it
    loss = np.empty(n_int)
    for e, lv in enumerate(levels):
        t = tracks[lv]
        margin = np.zeros(t.sigma.shape) if t.margin is None else t.margin
        edge_loss(dist[e] ** 2, frac[e], True, margin, t.sigma, ids, n_int, int(keep[e]) - 1,
                  lv == 0, d_min_m, loss)  # fmt: skip
        keeps *= 1.0 - loss
    chance = 1.0 - keeps
    order = np.argsort(-chance, kind="stable")
    losses = tuple((int(i), float(chance[i])) for i in order if chance[i] > 0)
    return losses, float(1.0 - np.prod(keeps))


def chord_distances(
    own: np.ndarray, intruders: np.ndarray, aspect: float | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """(..., n, N) closest distance on every sub-step to every intruder, and its fraction
    along the sub-step; ``own`` (..., n+1, 3), ``intruders`` (..., n+1, N, 3): one edge, or
    a batch of them. ``aspect``: in the conflict cylinder's norm (None: 3-D distance)."""
    rel = own[..., :, None, :] - intruders
    if aspect is None:
        return closest_on_pieces(rel[..., :-1, :, :], np.diff(rel, axis=-3))
    return closest_on_pieces_cylinder(rel[..., :-1, :, :], np.diff(rel, axis=-3), aspect)


def _first_conflict(
    dist: np.ndarray, track: Track, d_min_m: float, t0: float, dt: float
) -> tuple[int, float, float]:
    """(intruder index, time, separation needed) of the first sub-step of an edge where the
    line comes inside ``d_min`` plus an intruder's margin (a sub-step needs its end's margin,
    as the model holds it); the deepest intrusion on that sub-step names the intruder."""
    need = d_min_m + (0.0 if track.margin is None else track.margin[1:])
    need = np.broadcast_to(need, dist.shape)
    depth = need - dist
    inside = (depth > 0).any(axis=1)
    if inside.any():
        k = int(np.argmax(inside))
        j = int(np.argmax(depth[k]))
    else:  # decided on a hair's breadth by the search: its deepest approach
        k, j = np.unravel_index(int(np.argmax(depth)), depth.shape)
    return int(j), t0 + int(k) * dt, float(need[k, j])


def measured_children(
    children: Sequence[ChildStats],
    lines: dict[int, list[int]],
    tree: SearchTree,
    samples: dict[int, np.ndarray],
    t_events: dict[int, float],
    tracks: Sequence[Track],
    ids: Sequence,
    own: Ownship,
    config: PlannerConfig,
) -> tuple[list[ChildStats], dict[int, float]]:
    """A tree planner's root options quoting what their lines predict (:func:`measure_line`,
    all lines in one batch) and which manoeuvre each flies (:func:`flies`); and how far ahead
    each line reaches."""
    order = [lines[c.action] for c in children]
    dist, frac = _line_chords(order, tree, samples, tracks, config.cylinder_aspect)
    measures = measure_lines(
        dist,
        frac,
        [[int(tree.depth[node]) - 1 for node in line] for line in order],
        [[(int(tree.terminal[node]), t_events[node]) for node in line] for line in order],
        tracks,
        config.action_hold_s,
        config.d_min_m,
    )
    out, horizons = [], {}
    for c, m in zip(children, measures, strict=True):
        out.append(with_measure(c, m, ids, effect=flies(c.action, own, config)))
        horizons[c.action] = m.horizon_s
    return out, horizons


def _line_chords(
    lines: Sequence[list[int]],
    tree: SearchTree,
    samples: dict[int, np.ndarray],
    tracks: Sequence[Track],
    aspect: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """:func:`chord_distances` of every edge of ``lines``, in one batch (one call per edge
    costs more than the rest of the explanation), laid out (L, U, n, N) for
    :func:`measure_lines`: a shorter line's missing edges repeat its first."""
    nodes = [node for line in lines for node in line]
    n = samples[nodes[0]].shape[0] - 1
    width = max(len(line) for line in lines)
    if not tracks or not tracks[0].count:
        return (np.zeros((len(lines), width, n, 0)),) * 2
    levels = tree.depth[nodes] - 1
    dist, frac = chord_distances(
        np.stack([samples[node] for node in nodes]), np.stack([t.pos for t in tracks])[levels],
        aspect,
    )
    index = np.zeros((len(lines), width), dtype=int)
    at = 0
    for row, line in enumerate(lines):
        index[row, :] = at
        index[row, : len(line)] = np.arange(at, at + len(line))
        at += len(line)
    return dist[index], frac[index]


def with_measure(child: ChildStats, m: LineMeasure, ids: Sequence, **more) -> ChildStats:
    """``child`` quoting ``m``'s predictions (intruders named by their ids), and ``more``
    fields changed in the same copy."""
    meets = None
    if m.meets is not None:
        who, when, miss, needed = m.meets
        meets = Meeting(ids[who], when, miss, needed)
    return replace(
        child,
        predicted_min_separation_m=m.min_sep_m,
        closest_intruder=ids[m.closest] if m.closest >= 0 else None,
        time_to_closest_s=m.t_closest_s,
        meets=meets,
        unsure=tuple((ids[i], could) for i, could in m.unsure),
        losses=tuple((ids[i], chance) for i, chance in m.losses),
        risk=m.risk,
        **more,
    )


def flies(action: int, own: Ownship, config: PlannerConfig) -> int | None:
    """The action whose manoeuvre ``action`` flies from ``own`` once its commands are clamped
    (None: its own). A bank step that the bank limit cancels holds the bank command; a speed
    change that the speed limits cut below ``SPEED_CHANGE_SHARE`` of what it commands holds
    the speed; a climb (descend) that the vertical command's end cancels (already climbing or
    descending) keeps it."""
    a = ACTIONS[action]
    bank, accel, climb = a.bank, a.accel, a.climb
    if climb and vertical_command(own.vertical, action) == own.vertical:
        climb = 0
    # 1e-6 rad: a bank command read back through JSBSim (float32) sits up to ~1e-7 rad
    # beyond the limit the clamp returns; a step that small changes nothing.
    if bank and abs(float(bank_command(own.bank, action, config)) - own.bank) < 1e-6:
        bank = 0
    if accel:
        commanded = config.accel_mps2 * config.action_hold_s
        band = own.speed_band or config.speed_mps
        lo, hi = min(band[0], own.speed), max(band[1], own.speed)
        change = min(max(own.speed + accel * commanded, lo), hi) - own.speed
        if abs(change) < SPEED_CHANGE_SHARE * commanded or commanded == 0:
            accel = 0
    if (bank, accel, climb) == (a.bank, a.accel, a.climb):
        return None
    return next(b.index for b in ACTIONS if (b.bank, b.accel, b.climb) == (bank, accel, climb))


def conflicts(c: ChildStats) -> bool:
    """Does the option's line conflict (come inside the separation it needs)?"""
    return c.outcome == "collision" or c.meets is not None


def leaves(c: ChildStats) -> bool:
    """Does the option's line leave the flight area, or end where it can no longer stay in it
    (``trapped``: planners that weigh the walls, `mcts_sep`)?"""
    return c.outcome == Outcome.OUT_OF_BOUNDS or c.trapped


def search_key(c: ChildStats, by_value: bool = False) -> tuple:
    """How the tree search ranks root options (:meth:`SearchTree.best_child`): more
    simulations, then the higher Q, then action order; with ``by_value`` (the best-value
    backup, where Q is the best line found below) the higher Q first, then simulations."""
    return (c.q, c.visits, -c.action) if by_value else (c.visits, c.q, -c.action)


def cornered_key(
    c: ChildStats, by_value: bool = False, rule: str = "latest", d_min_m: float = math.nan
) -> tuple:
    """How a cornered planner ranks options (``rule``, `avoidance.mcts.cornered_rule`): a line
    that stays in the area before one that leaves it or ends unable to turn away from a wall
    (``trapped``; leaving is a failure for certain, a predicted meeting may still be turned
    into a miss by re-planning); then, "latest", the latest meeting, then the largest predicted
    miss of the intruder met; "widest", the widest predicted closest approach to any intruder
    along the line (no margins) up to :data:`WIDE_ENOUGH` x ``d_min_m`` (:func:`pass_width`),
    then the latest meeting, then the widest approach; then the search's preference
    (:func:`search_key`)."""
    m = c.meets
    if rule == "widest":
        return (not leaves(c), *widest_terms(c, d_min_m), *search_key(c, by_value))
    return (
        not leaves(c),
        _meeting_time(c),
        -math.inf if m is None else m.miss_m,
        *search_key(c, by_value),
    )


def _meeting_time(c: ChildStats) -> float:
    """When the option's line first meets an intruder, to the microsecond (-inf: never)."""
    return -math.inf if c.meets is None else round(c.meets.time_s, 6)


def widest_terms(c: ChildStats, d_min_m: float) -> tuple[float, float, float]:
    """The rule "widest"'s own terms for an option, best last: its pass width
    (:func:`pass_width`), its meeting time, its uncapped closest approach."""
    return (pass_width(c, d_min_m), _meeting_time(c), c.predicted_min_separation_m)


# The cornered rule "widest" ranks lines by their closest approach up to this many times the
# collision distance: a line predicted to pass everyone that wide is as good as any other such
# line, and the latest meeting decides between them as under "latest". Below it the wider the
# better (a graze is a line that passed one intruder wide and another just inside d_min).
# Without the cap (every width counted), 2 of the 16 development flights of a31's grazes left
# the area at the start corner instead (docs/results, "Issue 31: cornered, the widest pass").
WIDE_ENOUGH = 2.0


def pass_width(c: ChildStats, d_min_m: float) -> float:
    """The option's predicted closest approach to any intruder (m), counted up to
    :data:`WIDE_ENOUGH` x the collision distance ``d_min_m`` (the rule "widest")."""
    if not d_min_m > 0:
        raise ValueError(f"the cornered rule 'widest' needs the collision distance, got {d_min_m}")
    return min(c.predicted_min_separation_m, WIDE_ENOUGH * d_min_m)


def cornered_choice(
    children: Sequence[ChildStats],
    by_value: bool = False,
    rule: str = "latest",
    d_min_m: float = math.nan,
) -> ChildStats | None:
    """When every option's line conflicts, the one to take (:func:`cornered_key`), else None."""
    if not children or not all(conflicts(c) for c in children):
        return None
    return max(children, key=lambda c: cornered_key(c, by_value, rule, d_min_m))
