"""The `mvp` planner: the Modified Voltage Potential resolution of BlueSky's conflict
resolution (TU Delft; Hoekstra et al.), behind the planner API (README, planner API).

Each decision:

1. *Detection*, state-based as BlueSky's ``StateBased``: against every intruder, at the
   current velocities, the horizontal closest point of approach; a conflict is a loss of the
   protected zone (horizontal radius ``rpz``, half-height ``hpz``) that starts within the
   look-ahead time and has not ended. The zone is the collision cylinder around ``d_min_m``
   (``rpz = hpz = d_min``): it holds the 3-D ``d_min`` sphere.
2. *Resolution*, :func:`mvp_dv`, a line-by-line transcription of ``MVP.MVP`` in
   ``bluesky/traffic/asas/mvp.py``: for each conflict the velocity change that moves the
   closest point of approach out to the zone's edge (times BlueSky's resolution margin
   ``resofach``) by ``tcpa``; the ownship takes ``-dv`` of each (no priority rules, as
   BlueSky's default). Resolutions are horizontal (BlueSky's default ``RMETHH``: heading and
   speed); the new velocity ``v + sum dv`` gives a target track and a speed within the
   speed limits.
3. *Action*: without conflicts the target is the goal, at the current speed, except while
   a resolved pair has not yet passed its CPA (BlueSky's ``resumenav``): then the ownship
   holds its velocity. The planner takes the one of the 9 actions whose velocity, flown
   ``REALISE_S`` on the encounter model and then rolled wings level, comes closest to the
   target velocity.

The children of the decision are the 9 actions flown for ``action_hold_s`` on the encounter
model against the predicted intruders, so that explanations can compare them; ``q`` of a
child is ``1 / (1 + |v - v_mvp|)`` for that settled velocity (1 at the target), so the
chosen action has the highest and the runner-up is the next-best realisation of MVP.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from dataclasses import dataclass

import numpy as np

from uavxai.avoidance.lines import flies, measure_line, with_measure
from uavxai.avoidance.mcts import intruder_arrays, predict_levels
from uavxai.avoidance.model import (
    OUTCOME_NAMES,
    PHI,
    PSI,
    EncounterModel,
    Segment,
    V,
    accel_command,
    bank_command,
    ownship_state,
)
from uavxai.avoidance.types import (
    N_ACTIONS,
    ChildStats,
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
    check_plan_inputs,
)
from uavxai.geometry import bearing, turn_rate_of_bank

LOOKAHEAD_S = 20.0  # BlueSky's default is 300 s for 5 NM zones; 50 m zones need far less
RESO_FACTOR_H = 1.01  # BlueSky's asas_marh: horizontal resolution margin
RESO_FACTOR_V = 1.01  # asas_marv
# The planner's horizontal margin (BlueSky's RFACH): the 9 actions move the bank command in
# 10 deg steps once a second, too coarse to trim the few degrees MVP asks for near the zone
# edge, so the planner aims that much wider; mvp_dv keeps BlueSky's default.
PLANNER_RESO_FACTOR_H = 1.2
REALISE_S = 2.0  # how far ahead an action's velocity is compared with the MVP velocity, s
HEAD_ON_M = 10.0  # BlueSky's floor on the CPA distance (head-on conflicts)


@dataclass(frozen=True)
class Conflict:
    """One detected conflict, in BlueSky's terms (distances m, times s, qdr deg)."""

    index: int  # into the intruder list
    qdr_deg: float  # bearing from the ownship to the intruder, clockwise from north
    dist: float  # horizontal distance
    tcpa: float  # time to the horizontal closest point of approach
    tlos: float  # time to the loss of separation (tinconf)
    drel: np.ndarray  # (3,) intruder minus ownship position


def detect(
    own_pos: np.ndarray,
    own_vel: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    rpz: float,
    hpz: float,
    lookahead_s: float = LOOKAHEAD_S,
) -> list[Conflict]:
    """State-based conflict detection as BlueSky's ``StateBased.detect``, for one ownship.

    ``own_pos``/``own_vel`` (3,), ``pos``/``vel`` (N, 3) ENU. A pair is in conflict when
    its horizontal CPA lies inside ``rpz`` and the horizontal and vertical intrusion windows
    overlap, end after now and start within ``lookahead_s``.
    """
    out: list[Conflict] = []
    for j in range(len(pos)):
        d = pos[j] - own_pos  # intruder relative to the ownship
        dist = math.hypot(d[0], d[1])
        du, dv = own_vel[0] - vel[j, 0], own_vel[1] - vel[j, 1]  # ownship relative to it
        dv2 = max(du * du + dv * dv, 1e-6)
        vrel = math.sqrt(dv2)
        # the ownship closes on the intruder along (du, dv); CPA when that is along d
        tcpa = (du * d[0] + dv * d[1]) / dv2
        dcpa2 = abs(dist * dist - tcpa * tcpa * dv2)
        if dcpa2 >= rpz * rpz:
            continue
        dtin = math.sqrt(max(0.0, rpz * rpz - dcpa2)) / vrel
        tinhor, touthor = tcpa - dtin, tcpa + dtin
        dalt = own_pos[2] - pos[j, 2]
        dvs = own_vel[2] - vel[j, 2]
        if abs(dvs) > 1e-9:
            t1, t2 = (dalt + hpz) / -dvs, (dalt - hpz) / -dvs
            tinver, toutver = min(t1, t2), max(t1, t2)
        elif abs(dalt) < hpz:
            tinver, toutver = -math.inf, math.inf
        else:
            continue
        tin, tout = max(tinver, tinhor), min(toutver, touthor)
        if tin <= tout and tout > 0.0 and tin < lookahead_s:
            qdr = math.degrees(math.atan2(d[0], d[1]))
            out.append(Conflict(j, qdr, dist, tcpa, tin, d))
    return out


def mvp_dv(
    drel: np.ndarray,
    v1: np.ndarray,
    v2: np.ndarray,
    dist: float,
    tcpa: float,
    tlos: float,
    rpz: float,
    hpz: float,
    lookahead_s: float = LOOKAHEAD_S,
    resofach: float = RESO_FACTOR_H,
    resofacv: float = RESO_FACTOR_V,
) -> tuple[np.ndarray, float]:
    """BlueSky's ``MVP.MVP`` for one pair: the (3,) velocity change ``dv_mvp`` (the ownship
    applies ``-dv_mvp``) and the time to solve vertically. ``drel`` is intruder minus ownship
    (east, north, up), ``v1``/``v2`` the ownship's and intruder's velocities."""
    rpz_m = rpz * resofach
    hpz_m = hpz * resofacv
    drel = np.asarray(drel, dtype=float)
    vrel = np.asarray(v2, dtype=float) - np.asarray(v1, dtype=float)

    # Horizontal: the CPA vector, pushed out to the zone's edge by tcpa.
    dcpa = drel + vrel * tcpa
    dabs_h = math.sqrt(dcpa[0] * dcpa[0] + dcpa[1] * dcpa[1])
    i_h = rpz_m - dabs_h
    if dabs_h <= HEAD_ON_M:  # head-on: resolve perpendicular to the line of sight
        dabs_h = HEAD_ON_M
        dcpa[0] = drel[1] / dist * dabs_h
        dcpa[1] = -drel[0] / dist * dabs_h
    if rpz_m < dist and dabs_h < dist:
        # outside the zone: the extra factor keeps the resolution from grazing it
        erratum = math.cos(math.asin(rpz_m / dist) - math.asin(dabs_h / dist))
        dv1 = ((rpz_m / erratum - dabs_h) * dcpa[0]) / (abs(tcpa) * dabs_h)
        dv2 = ((rpz_m / erratum - dabs_h) * dcpa[1]) / (abs(tcpa) * dabs_h)
    else:
        dv1 = (i_h * dcpa[0]) / (abs(tcpa) * dabs_h)
        dv2 = (i_h * dcpa[1]) / (abs(tcpa) * dabs_h)

    # Vertical.
    i_v = hpz_m if abs(vrel[2]) > 0.0 else hpz_m - abs(drel[2])
    tsol_v = abs(drel[2] / vrel[2]) if abs(vrel[2]) > 0.0 else tlos
    if tsol_v > lookahead_s:
        tsol_v = tlos
        i_v = hpz_m
    dv3 = (i_v / tsol_v) * (-vrel[2] / abs(vrel[2])) if abs(vrel[2]) > 0.0 else i_v / tsol_v
    return np.array([dv1, dv2, dv3]), tsol_v


def resolve(
    own_pos: np.ndarray,
    own_vel: np.ndarray,
    pos: np.ndarray,
    vel: np.ndarray,
    rpz: float,
    hpz: float,
    lookahead_s: float = LOOKAHEAD_S,
    resofach: float = RESO_FACTOR_H,
) -> tuple[np.ndarray, list[Conflict]]:
    """The ownship's (3,) resolution velocity change, summed over its conflicts as BlueSky's
    ``MVP.resolve`` does without priority rules (the vertical part halved: cooperative), and
    the conflicts."""
    conflicts = detect(own_pos, own_vel, pos, vel, rpz, hpz, lookahead_s)
    dv = np.zeros(3)
    for c in conflicts:
        dv_mvp, _ = mvp_dv(c.drel, own_vel, vel[c.index], c.dist, c.tcpa, c.tlos, rpz, hpz,
                           lookahead_s, resofach)  # fmt: skip
        dv_mvp[2] *= 0.5
        dv -= dv_mvp
    return dv, conflicts


class MVPPlanner:
    """Modified Voltage Potential conflict resolution (BlueSky) over the 9 actions."""

    def __init__(self, config: PlannerConfig | None = None, *, name: str = "mvp") -> None:
        self.config = (config or PlannerConfig()).whole_goal()
        self.name = name
        self.model = EncounterModel(self.config)
        self.lookahead_s = LOOKAHEAD_S
        self.resofach = PLANNER_RESO_FACTOR_H
        self._resolving: set = set()  # ids of pairs resolved but not yet past their CPA

    def reset(self, seed: int) -> None:
        """Nothing random; forgets the pairs under resolution (a new episode)."""
        self._resolving = set()

    def _resume(self, own_pos: np.ndarray, own_vel: np.ndarray, intruders) -> bool:
        """BlueSky's ``resumenav``: a pair stays under resolution until it is past its CPA
        (diverging) and outside the zone; meanwhile the ownship keeps its velocity instead of
        turning back for the goal (and into the conflict again). True: some pair still is."""
        by_id = {i.id: i for i in intruders}
        keep = set()
        for ident in self._resolving:
            i = by_id.get(ident)
            if i is None:
                continue
            d = (i.x - own_pos[0], i.y - own_pos[1])
            v = (i.vx - own_vel[0], i.vy - own_vel[1])
            diverging = d[0] * v[0] + d[1] * v[1] > 0.0
            if not diverging or math.hypot(*d) < self.config.d_min_m * RESO_FACTOR_H:
                keep.add(ident)
        self._resolving = keep
        return bool(keep)

    def target(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal
    ) -> tuple[float, float, list[Conflict], np.ndarray]:
        """(track, speed) the planner steers for, the conflicts and the velocity change."""
        cfg = self.config
        own_vel = np.array(
            [own.speed * math.sin(own.heading), own.speed * math.cos(own.heading), 0.0]
        )
        own_pos = np.array([own.x, own.y, own.h])
        pos, vel = intruder_arrays(intruders)
        dv, conflicts = resolve(own_pos, own_vel, pos, vel, cfg.d_min_m, cfg.d_min_m,
                                self.lookahead_s, self.resofach)  # fmt: skip
        if conflicts:
            self._resolving |= {intruders[c.index].id for c in conflicts}
        elif self._resume(own_pos, own_vel, intruders):
            return own.heading, own.speed, conflicts, dv  # hold the resolution velocity
        else:
            return bearing(goal[0] - own.x, goal[1] - own.y), own.speed, conflicts, dv
        new = own_vel + dv
        speed = min(max(math.hypot(new[0], new[1]), cfg.speed_mps[0]), cfg.speed_mps[1])
        return bearing(new[0], new[1]), speed, conflicts, dv

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        t0 = time.perf_counter()
        check_plan_inputs(own, intruders, goal)
        cfg = self.config
        track, speed, conflicts, _ = self.target(own, intruders, goal)
        goal_xyz = np.asarray(goal, dtype=float)
        state = ownship_state(own)
        action, miss = self._realise(state, goal_xyz, track, speed)
        seg, children, horizon = self._evidence(own, state, goal_xyz, intruders, action, miss)
        pos, vel = intruder_arrays(intruders)
        period = cfg.decision_period_s
        nxt = self.model.fly(
            state[None], np.array([action]), goal_xyz, period,
            self.model.predict(pos, vel, period, index=False), cull=False, exact=True,
        )  # fmt: skip
        decision = Decision(
            bank_cmd_rad=float(bank_command(own.bank, action, cfg)),
            accel_mps2=float(accel_command(action, cfg)),
            action=action,
            children=children,
            plan=seg.samples[action],
            predicted_min_separation_m=float(nxt.min_sep[0]),
            confidence=1.0,
            planner=self.name,
            d_min_m=cfg.d_min_m,
            branch_min_separation_m=children[action].predicted_min_separation_m,
            branch_horizon_s=horizon,
        )
        # MVP's own reason; the options' separations are evidence
        decision.words = (self._reason(conflicts, intruders, track, speed), "")
        decision.ms = 1000.0 * (time.perf_counter() - t0)
        return decision

    def _realise(
        self, state: np.ndarray, goal_xyz: np.ndarray, track: float, speed: float
    ) -> tuple[int, np.ndarray]:
        """The action that best realises the MVP velocity, and every action's miss (m/s).

        Every action flown REALISE_S on the model (roll-rate limits included), then the track
        it would settle on rolling wings level; the action whose settled velocity comes closest
        wins (ties: hold bank, hold speed). A proportional bank law over 10 deg steps either
        stalls in its dead band (a 4 deg correction rounds to "hold") or overshoots; this
        realises small corrections too.
        """
        nobody = np.zeros((0, 3))
        after = self.model.fly(
            np.repeat(state[None], N_ACTIONS, axis=0), np.arange(N_ACTIONS), goal_xyz,
            REALISE_S, self.model.predict(nobody, nobody, REALISE_S, index=False),
        ).end  # fmt: skip
        v_end, phi = after[:, V], after[:, PHI]
        roll_out_s = np.abs(phi) / math.radians(self.config.roll_rate_limit_deg_s)
        settled = after[:, PSI] + 0.5 * roll_out_s * turn_rate_of_bank(phi, v_end)
        v_settled = v_end[:, None] * np.stack([np.sin(settled), np.cos(settled)], axis=1)
        target_v = speed * np.array([math.sin(track), math.cos(track)])
        miss = np.linalg.norm(v_settled - target_v, axis=1)
        prefer = [4, 1, 7, 3, 5, 0, 2, 6, 8]  # hold first, then bank alone, then speed
        action = min(prefer, key=lambda a: (round(float(miss[a]), 9), prefer.index(a)))
        return action, miss

    def _evidence(
        self,
        own: Ownship,
        state: np.ndarray,
        goal_xyz: np.ndarray,
        intruders: Sequence[Intruder],
        action: int,
        miss: np.ndarray,
    ) -> tuple[Segment, list[ChildStats], float]:
        """Evidence for the explanation: every action flown against the predicted traffic;
        and how far ahead the chosen action's line reaches.

        MVP does not search, so these separations only illustrate the options; ``q`` scores
        how closely each realises the MVP velocity.
        """
        cfg = self.config
        hold = cfg.action_hold_s
        seg = self.model.fly(
            np.repeat(state[None], N_ACTIONS, axis=0),
            np.arange(N_ACTIONS),
            goal_xyz,
            hold,
            track := predict_levels(self.model, intruders, 1, hold)[0],
            cull=False,
            exact=True,
        )
        ids = [i.id for i in intruders]
        children, horizon = [], hold
        for a in range(N_ACTIONS):
            known = bool(np.isfinite(seg.min_sep[a])) and int(seg.closest[a]) >= 0
            children.append(
                ChildStats(
                    action=a,
                    bank_cmd_rad=float(bank_command(own.bank, a, cfg)),
                    accel_mps2=float(accel_command(a, cfg)),
                    visits=1 if a == action else 0,
                    q=1.0 / (1.0 + float(miss[a])),
                    predicted_min_separation_m=float(seg.min_sep[a]),
                    closest_intruder=ids[int(seg.closest[a])] if known else None,
                    time_to_closest_s=float(seg.t_closest[a]) if known else None,
                    outcome=OUTCOME_NAMES[int(seg.event[a])],
                    effect=flies(a, own, cfg),
                )
            )
            # quoted as the tree planners quote theirs: on the tracks as predicted, a
            # collision's predicted miss (uavxai.avoidance.lines)
            end = (int(seg.event[a]), float(seg.t_event[a]))
            line = measure_line([seg.samples[a]], [0], [end], [track], hold, cfg.d_min_m)
            children[-1] = with_measure(children[-1], line, ids)
            horizon = line.horizon_s if a == action else horizon
        return seg, children, horizon

    def _reason(
        self, conflicts: list[Conflict], intruders: Sequence[Intruder], track: float, speed: float
    ) -> str:
        """MVP's own one-line reason: the conflicts it resolves, or that there are none."""
        if conflicts:
            first = min(conflicts, key=lambda k: k.tlos)
            return (
                f"MVP resolves {len(conflicts)} conflict(s), first with "
                f"{intruders[first.index].id} in {max(first.tlos, 0.0):.0f} s: "
                f"track {math.degrees(track) % 360:.0f} deg at {speed:.1f} m/s"
            )
        return f"MVP: no conflict within {self.lookahead_s:.0f} s, steering for the goal"
