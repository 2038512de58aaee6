"""Explanations of avoidance decisions in plain words, and `uavxai explain RUN_DIR`.

Everything here is read off data the planner returned (the per-root-action statistics of its
search: visits, Q, predicted minimum separation, closest intruder and when), so a sentence is
never more confident than the search was. :func:`explain` turns a :class:`Decision` into the
sentence and the counterfactual for the runner-up; :func:`decision_record` is the line written
to ``decisions.jsonl``; :func:`explain_command` reads that file back and renders it.
"""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

from uavxai.avoidance.lines import (
    WIDE_ENOUGH,
    conflicts,
    cornered_key,
    leaves,
    pass_width,
    search_key,
    widest_terms,
)
from uavxai.avoidance.types import ChildStats, Decision, Intruder, Ownship, set_narrator
from uavxai.errors import UserError
from uavxai.vocabulary import ACTIONS, HOLD


# ----------------------------------------------------------------------------- one decision
def explain(decision: Decision) -> tuple[str, str]:
    """(sentence, counterfactual) for a decision, e.g.

    "banked right: holding bank and speed meets intruder 7 in 9.0 s (predicted miss 21 m, 74 m
    needed); right is predicted to keep 180 m from intruder 3; 71% of simulations agree" and
    "why not left: ...".

    The verb says the manoeuvre flown: an action whose command is clamped (a bank step at
    the bank limit, a speed change at the speed limit) is said to change nothing; options
    are named as in the table of root actions, and one that flies the chosen manoeuvre is
    never offered as an alternative to it.
    Separations are predictions (:class:`ChildStats`), and are worded as such.
    """
    by_action = {c.action: c for c in decision.children}
    chosen = by_action.get(decision.action)
    if chosen is None:  # a planner without a search behind it
        verb = ACTIONS[decision.action].verb
        return f"{verb} ({decision.planner or 'planner'} gives no reasons)", ""
    parts: list[str] = []
    if decision.cornered:
        parts.append(_cornered(chosen, decision))
        parts.append(f"{_short(chosen.action)} {_meets(chosen)}")
    elif decision.route_kept:
        parts.append(f"it keeps to its route, whose line ({_short(chosen.action)}) "
                     f"{_keeps(chosen, decision)}, no predicted conflict")  # fmt: skip
    else:
        hold = by_action.get(HOLD)
        if _all_end(decision):
            parts.append(_all_end(decision))
        if hold is not None and hold.flies != chosen.flies:
            parts.append(_reference(hold, chosen, decision))
        parts.append(f"{_short(chosen.action)} {_keeps(chosen, decision)}")
    parts.append(_support(decision))
    sentence = f"{ACTIONS[chosen.flies].verb}{_clamped(chosen)}: " + "; ".join(parts)
    return sentence, counterfactual(decision)


def counterfactual(decision: Decision) -> str:
    """Why not the runner-up: the best other manoeuvre by the rule the planner chose by."""
    chosen = next((c for c in decision.children if c.action == decision.action), None)
    if chosen is None:
        return ""
    runner = _runner(decision, chosen, cornered=decision.cornered)
    if runner is None:
        return ""
    head = f"why not {_short(runner.action)}{_flies_as(runner)}"
    if decision.cornered:
        return f"{head}: {_cornered_loser(runner, chosen, decision)}"
    if decision.route_kept:
        return (f"{head}: the search preferred it ({runner.visits} simulations against "
                f"{chosen.visits}, Q {runner.q:.3f} against {chosen.q:.3f}), but it leaves the "
                "route, and the route's line has no conflict to avoid")  # fmt: skip
    if _conflict(runner, decision.d_min_m):
        if not _conflict(chosen, decision.d_min_m):
            return f"{head}: it {_meets(runner)}, {_breach(runner, decision.d_min_m)}"
        return f"{head}: it {_meets(runner)} too; {_q_against(runner, chosen, decision)}"
    reason = _q_against(runner, chosen, decision)
    if math.isfinite(runner.predicted_min_separation_m) and runner.closest_intruder is not None:
        reason += f"; it {_keeps(runner, decision)}"
    elif runner.outcome in _ENDS:  # _keeps says it otherwise
        reason += f"; its best line {_ends(runner, chosen)}"
    if runner.pinned and runner.q < chosen.q and _pin_kept(runner) < _pin_kept(chosen):
        reason += f"; its best line {_pinned(runner)}"
    return f"{head}: {reason}"


def _pin_kept(c: ChildStats) -> float:
    """The share of its value a line keeps for the tracks pinning its end (their product,
    as the search weighed it: kernel.pinned_factor)."""
    return math.prod(share for _, share in c.pinned)


def _pinned(c: ChildStats) -> str:
    """How a line's end is pinned (``ChildStats.pinned``: the tightest track first)."""
    who, _ = c.pinned[0]
    more = f" and {len(c.pinned) - 1} more" if len(c.pinned) > 1 else ""
    kept = _pin_kept(c)
    return (
        f"ends pinned by {_name(who)}{more}: too little room between that track and the "
        "floor's or the ceiling's level-off to let it pass over or under the ownship "
        f"(keeps {_percent(kept) if kept > 0 else 'none'} of its value)"
    )


_ENDS = ("out_of_bounds", "timeout")  # line ends the words name (goal: "reaches the goal")


def _ends(c: ChildStats, chosen: ChildStats | None) -> str:
    """How an option's best line ends, "too" when the chosen one's ends so as well: then it
    is no reason against it (issue 30: "ends out of bounds" given as the reason when every
    option did and action order decided)."""
    same = chosen is not None and c is not chosen and chosen.outcome == c.outcome
    return _end_words(c.outcome) + (" too" if same else "")


def _all_end(decision: Decision) -> str:
    """ "every option ends out of bounds" when no option escapes that end, else ""."""
    ends = {c.outcome for c in decision.children}
    if len(ends) != 1 or not ends <= set(_ENDS):
        return ""
    return "every option " + _end_words(ends.pop())


def _end_words(outcome: str) -> str:
    return "ends out of bounds" if outcome == "out_of_bounds" else "ends at the time-out"


def _breach(c: ChildStats, d_min: float) -> str:
    """What a conflict predicted: a collision (inside ``d_min``), or a pass inside the
    margin kept beyond it, which the search counts as one (issue 30)."""
    m = c.meets
    if m is None or m.miss_m < d_min:
        return "a predicted collision"
    return (
        f"inside the {m.needed_m - d_min:.0f} m margin kept beyond the {d_min:.0f} m collision "
        "distance for what that intruder may do, which the search counts as a collision"
    )


def runner_up(
    children: Sequence[ChildStats],
    chosen: ChildStats,
    *,
    cornered: bool = False,
    by_value: bool = False,
    rule: str = "latest",
    d_min_m: float = math.nan,
) -> ChildStats | None:
    """The best option that flies another manoeuvre than ``chosen``: by the cornered rule
    (``rule``, with the collision distance ``d_min_m`` it may weigh) when the planner chose by
    it, else as the search ranks (:func:`search_key`; ``by_value``: Q first, the best-value
    backup)."""
    others = [c for c in children if c.flies != chosen.flies]
    if not others:
        return None
    if cornered:
        return max(others, key=lambda c: cornered_key(c, by_value, rule, d_min_m))
    return max(others, key=lambda c: search_key(c, by_value))


def _runner(decision: Decision, chosen: ChildStats, *, cornered: bool) -> ChildStats | None:
    """:func:`runner_up` by the rules ``decision`` was made by."""
    return runner_up(
        decision.children, chosen, cornered=cornered, by_value=decision.by_value,
        rule=decision.cornered_rule, d_min_m=decision.d_min_m,
    )  # fmt: skip


def is_avoidance(children: Sequence[ChildStats], action: int, d_min_m: float) -> bool:
    """Did the decision steer away from a predicted conflict: holding bank and speed conflicts,
    the chosen manoeuvre (another one) does not."""
    by_action = {c.action: c for c in children}
    chosen, hold = by_action.get(action), by_action.get(HOLD)
    if chosen is None or hold is None or chosen.flies == hold.flies:
        return False
    return _conflict(hold, d_min_m) and not _conflict(chosen, d_min_m)


def _reference(hold: ChildStats, chosen: ChildStats, decision: Decision) -> str:
    held = ACTIONS[HOLD].phrase
    if _conflict(hold, decision.d_min_m):
        return f"{held} {_meets(hold)}"
    if hold.outcome in _ENDS and chosen.outcome != hold.outcome:
        return f"{held} {_ends(hold, chosen)}"
    if _tied(hold, chosen):  # e.g. near the goal, where every line reaches it
        return f"{held} is as good (Q {chosen.q:.3f}), {_why_this_one(chosen, hold, decision)}"
    if hold.q > chosen.q:  # chosen for its simulations, not its value: say so, not "lower"
        return (
            f"{held} has the higher Q ({hold.q:.3f} against {chosen.q:.3f}{_risk(hold)}) but "
            f"fewer simulations ({hold.visits} against {chosen.visits})"
        )
    return f"{held} scores lower (Q {hold.q:.3f} against {chosen.q:.3f}{_risk(hold)})"


def _q_against(runner: ChildStats, chosen: ChildStats, decision: Decision) -> str:
    """How the search ranked a rejected option against the chosen one, with what decided."""
    if _tied(runner, chosen):
        return f"as good (Q {chosen.q:.3f} both), {_why_this_one(chosen, runner, decision)}"
    if runner.q > chosen.q:
        return (
            f"a higher Q ({runner.q:.3f} against {chosen.q:.3f}{_risk(runner)}) but fewer "
            f"simulations ({runner.visits} against {chosen.visits})"
        )
    text = f"Q {runner.q:.3f} against {chosen.q:.3f}"
    if _sampled(decision):  # in an exhaustive search every sequence is scored once
        text += f" ({runner.visits} simulations against {chosen.visits}{_risk(runner)})"
    return text


def _why_this_one(chosen: ChildStats, other: ChildStats, decision: Decision) -> str:
    """What decided between two options of equal printed Q, as the search decides: the more
    simulated one (MCTS), then the higher Q, then action order (with the best-value backup,
    ``by_value``, and in the exhaustive search the higher Q first). Never claims "more
    simulations" on a tie of visits."""
    if not _sampled(decision) or (decision.by_value and chosen.q > other.q):
        if chosen.q > other.q:
            return "a higher Q beyond 3 decimals decided"
        return "the tie goes to the first in action order"
    if chosen.visits > other.visits:
        return f"this one had more simulations ({chosen.visits} against {other.visits})"
    if chosen.visits == other.visits:
        if chosen.q > other.q:
            return f"as many simulations ({chosen.visits} each): a higher Q beyond 3 decimals"
        return f"as many simulations ({chosen.visits} each) and Q: the first in action order"
    return f"though it had fewer simulations ({chosen.visits} against {other.visits})"


def _cornered(chosen: ChildStats, decision: Decision) -> str:
    """Every option conflicts: which rule picked this one, against the best other."""
    head = "every option meets an intruder, so it took the one that "
    m = chosen.meets
    if decision.cornered_rule == "widest":
        return head + _widest(chosen, decision)
    later = [c for c in decision.children if leaves(c) and _later(c, m)]
    if not leaves(chosen) and later:
        head += _stays_in(later)
    runner = _runner(decision, chosen, cornered=True)
    if runner is None or m is None or runner.meets is None:
        return head + "meets its intruder latest"
    r = runner.meets
    if round(m.time_s, 6) != round(r.time_s, 6):
        latest = f"in {m.time_s:.1f} s, the next in {r.time_s:.1f} s"
        return head + f"meets its intruder latest ({latest})"
    if m.miss_m != r.miss_m:
        return head + (
            f"meets its intruder latest (in {m.time_s:.1f} s, as another does) and passes it "
            f"widest ({m.miss_m:.1f} m against {r.miss_m:.1f} m)"
        )
    tie = _why_this_one(chosen, runner, decision)
    return head + f"meets its intruder latest and passes it widest, tied: {tie}"


def _stays_in(better: Sequence[ChildStats], how: str = "meets later") -> str:
    """The words for keeping in the area against ``better`` options that leave it (``how``:
    what makes them better by the rule)."""
    out = any(not c.trapped for c in better)
    return (f"stays in the flight area (an option that {how} "
            f"{'leaves it' if out else 'can no longer stay in it'}) and ")  # fmt: skip


def _metres(a: float, b: float) -> tuple[str, str]:
    """Two separations as words that tell them apart: one decimal, or two where one would
    print them the same (a rule decided by under 0.1 m must not read "49.7 m against 49.7 m")."""
    if f"{a:.1f}" != f"{b:.1f}":
        return f"{a:.1f} m", f"{b:.1f} m"
    return f"{a:.2f} m", f"{b:.2f} m"


def _widest(chosen: ChildStats, decision: Decision) -> str:
    """The cornered rule "widest" in words: the widest pass (counted up to WIDE_ENOUGH d_min),
    then the latest meeting, then the wider pass beyond that."""
    d_min, by_value = decision.d_min_m, decision.by_value
    mine_terms = widest_terms(chosen, d_min)
    better_out = [c for c in decision.children
                  if leaves(c) and widest_terms(c, d_min) > mine_terms]  # fmt: skip
    stays = not leaves(chosen)
    head = _stays_in(better_out, "passes wider or meets later") if stays and better_out else ""
    among = " of the options that stay in the area" if head else ""
    # against the best other that keeps in the area as this one does (the head says why a
    # wider one that leaves lost)
    peers = [c for c in decision.children if c.flies != chosen.flies and stays != leaves(c)]
    sep = chosen.predicted_min_separation_m
    if not peers:
        return head + f"passes the traffic at {sep:.1f} m from the nearest intruder"
    runner = max(peers, key=lambda c: cornered_key(c, by_value, "widest", d_min))
    r_sep = runner.predicted_min_separation_m
    if pass_width(chosen, d_min) != pass_width(runner, d_min):
        mine, theirs = _metres(sep, r_sep)
        return head + (f"passes the traffic widest{among} ({mine} from the nearest intruder "
                       f"against {theirs})")  # fmt: skip
    wide = f"{WIDE_ENOUGH * d_min:.0f} m or more" if sep >= WIDE_ENOUGH * d_min else f"{sep:.1f} m"
    head += f"passes the traffic as wide as another ({wide}) and "
    m, r = chosen.meets, runner.meets
    if m is not None and r is not None and round(m.time_s, 6) != round(r.time_s, 6):
        t, t2 = m.time_s, r.time_s
        return head + f"meets its intruder latest (in {t:.1f} s, the next in {t2:.1f} s)"
    if sep != r_sep:
        mine, theirs = _metres(sep, r_sep)
        return head + f"meets its intruder as late, passing wider ({mine} against {theirs})"
    return head + f"meets its intruder as late, tied: {_why_this_one(chosen, runner, decision)}"


def _later(c: ChildStats, m) -> bool:
    """Does ``c``'s line meet its intruder later than meeting ``m`` (or not at all)?"""
    return c.meets is None or m is None or c.meets.time_s > m.time_s


def _cornered_loser(runner: ChildStats, chosen: ChildStats, decision: Decision) -> str:
    if leaves(runner) and not leaves(chosen):
        if runner.trapped:
            return f"it {_meets(runner)} and can no longer turn away from the area's edge"
        return f"it {_meets(runner)} and leaves the flight area"
    m, r = chosen.meets, runner.meets
    if m is None or r is None:
        return f"it {_meets(runner)} too"
    if decision.cornered_rule == "widest":
        d_min, sep = decision.d_min_m, runner.predicted_min_separation_m
        if pass_width(runner, d_min) != pass_width(chosen, d_min):
            theirs, mine = _metres(sep, chosen.predicted_min_separation_m)
            return (f"it {_meets(runner)}, and comes nearer the traffic ({theirs} from the "
                    f"nearest intruder against {mine})")  # fmt: skip
    if round(m.time_s, 6) != round(r.time_s, 6):
        return f"it {_meets(runner)}, sooner"
    if decision.cornered_rule == "widest":
        if runner.predicted_min_separation_m != chosen.predicted_min_separation_m:
            return f"it {_meets(runner)}, as soon and nearer the traffic"
    elif m.miss_m != r.miss_m:
        return f"it {_meets(runner)}, as soon and closer"
    return f"it {_meets(runner)}, the same; {_why_this_one(chosen, runner, decision)}"


def _sampled(decision: Decision) -> bool:
    """Do visits count simulations (MCTS) rather than one per sequence (exhaustive)?"""
    return not decision.planner.startswith("exhaustive")


def _tied(a: ChildStats, b: ChildStats) -> bool:
    """Equal as printed (3 decimals): saying "lower" about 1.000 against 1.000 would mislead."""
    return f"{a.q:.3f}" == f"{b.q:.3f}"


def _risk(c: ChildStats) -> str:
    """How often the search saw an action end in a collision, when it did."""
    if c.collision_share is None or c.collision_share < 0.005:
        return ""
    return f"; {100 * c.collision_share:.0f}% of its simulations collide"


def _keeps(c: ChildStats, decision: Decision) -> str:
    if _conflict(c, decision.d_min_m):
        text = _meets(c)
        if all(_conflict(o, decision.d_min_m) for o in decision.children):
            text += "; every option meets an intruder"
        return text
    if c.closest_intruder is None or not math.isfinite(c.predicted_min_separation_m):
        text = "keeps clear of every known intruder"
    else:
        text = (
            f"is predicted to keep {c.predicted_min_separation_m:.0f} m from "
            f"{_name(c.closest_intruder)}"
        )
    if c.outcome == "goal":
        text += " and reaches the goal"
    elif c.outcome in _ENDS:
        chosen = next((o for o in decision.children if o.action == decision.action), None)
        text += f" and {_ends(c, chosen)}"
    if c.closest_intruder is not None and c.unsure:
        text += f"; {_unsure(c)}"
    if c.losses:
        text += f"; {_losses(c)}"
    return text


UNSURE_SHOWN = 2  # intruders named; the others counted


def _unsure(c: ChildStats) -> str:
    """The intruders the prediction is not sure of: within the margin kept for what each may
    do and its track error, it could pass closer than the one named (issue 30: "keeps N m
    from k" named one intruder while another passed closer)."""
    named = ", ".join(f"{_name(who)} (could pass at {m:.0f} m)"
                      for who, m in c.unsure[:UNSURE_SHOWN])  # fmt: skip
    more = len(c.unsure) - UNSURE_SHOWN
    return f"less sure of {named}" + (f" and {more} more" if more > 0 else "")


def _losses(c: ChildStats) -> str:
    """With risk as a probability, what the search weighed the line by (issue 31): "the
    chance of losing separation with intruder 7 along this line is 3 %", and with the
    others too when they add to it."""
    who, p = c.losses[0]
    text = f"the chance of losing separation with {_name(who)} along this line is {_percent(p)}"
    if c.risk is not None and len(c.losses) > 1:
        text += f" ({_percent(c.risk)} with any of {len(c.losses)} intruders)"
    return text


def _percent(p: float) -> str:
    """A chance in words: whole percent, and below 1 % as "under 1 %" (not "0 %")."""
    return "under 1 %" if p < 0.005 else f"{100 * p:.0f} %"


def _support(decision: Decision) -> str:
    if not _sampled(decision):
        if decision.cornered:  # chosen by the rule above, not by its value
            return "every action sequence to the search depth scored"
        return "the best of every action sequence to the search depth"
    if decision.route_kept:  # chosen by the route rule, not by its simulations
        return f"{100 * decision.confidence:.0f}% of simulations went to it"
    return f"{100 * decision.confidence:.0f}% of simulations agree"


def _conflict(c: ChildStats, d_min: float) -> bool:
    return conflicts(c) or c.predicted_min_separation_m < d_min


def _meets(c: ChildStats) -> str:
    m = c.meets
    if m is None:  # a planner that does not measure its conflicts
        who = _name(c.closest_intruder) if c.closest_intruder is not None else "an intruder"
        return f"meets {who}"
    return (
        f"meets {_name(m.intruder)} in {m.time_s:.1f} s (predicted miss {m.miss_m:.0f} m, "
        f"{m.needed_m:.0f} m needed)"
    )


def _clamped(c: ChildStats) -> str:
    """What a clamped command did not do, e.g. " (right changes nothing: the bank command is
    at its limit)"; "" when the action flies as itself."""
    if c.effect is None:
        return ""
    return f" ({ACTIONS[c.action].phrase} changes nothing: {_limits(c)})"


def _flies_as(c: ChildStats) -> str:
    """ " (flies as left: the speed is at its limit)" for a clamped option."""
    if c.effect is None:
        return ""
    return f" (flies as {_short(c.flies)}: {_limits(c)})"


def _limits(c: ChildStats) -> str:
    asked, flown = ACTIONS[c.action], ACTIONS[c.flies]
    limits = []
    if asked.bank != flown.bank:
        limits.append("the bank command")
    if asked.accel != flown.accel:
        limits.append("the speed")
    if asked.climb != flown.climb:
        limits.append("the vertical command")
    if len(limits) > 1:
        return " and ".join(limits) + " are at their limits"
    return f"{limits[0]} is at its limit"


def _short(action: int) -> str:
    return ACTIONS[action].phrase


def _name(intruder_id: Any) -> str:
    text = str(intruder_id)
    if text.startswith("ownship-"):  # a fleet member in another member's picture
        return f"fleet member {text.removeprefix('ownship-')}"
    if text.startswith("intruder-"):
        text = text.removeprefix("intruder-")
    return f"intruder {text}"


# ------------------------------------------------------------------------ decisions.jsonl
def decision_record(
    t: float, own: Ownship, intruders: Iterable[Intruder], decision: Decision
) -> dict[str, Any]:
    """One line of decisions.jsonl (README, "What a run produces"): time, what the planner
    saw, what it decided."""
    state = {
        "ownship": {
            "x": own.x,
            "y": own.y,
            "h": own.h,
            "speed": own.speed,
            "heading": own.heading,
            "bank": own.bank,
            "vertical": own.vertical,  # the vertical command (+1 climbing, -1 descending)
            # the speeds the planner may fly (None: the planner's own): an operator's airspeed
            # or the orbit's caps it, and a speed change beyond it changes nothing
            "speed_band": None if own.speed_band is None else list(own.speed_band),
        },
        # What the planner believed (README, decisions.jsonl): the track and how sure it was.
        "intruders": [
            {
                "id": i.id,
                "x": i.x,
                "y": i.y,
                "h": i.h,
                "vx": i.vx,
                "vy": i.vy,
                "vh": i.vh,
                "turn_rate": i.turn_rate,
                "sigma_m": i.sigma_m,
                "sigma_v": i.sigma_v,
                "age_s": i.age_s,
                # the bank limit its turn cover assumed (its aircraft's, issue 31); None: the
                # planner's avoidance.mcts.intruder_bank_limit_deg
                "bank_limit_deg": i.bank_limit_deg,
                # its height's own errors (the vertical margin, avoidance.mcts.
                # vertical_reach_mps); None: the horizontal ones stand in
                "sigma_h_m": i.sigma_h_m,
                "sigma_vh": i.sigma_vh,
                "keep_m": i.keep_m,  # a fleet member's clearance beyond d_min; 0 for traffic
            }
            for i in intruders
        ],
    }
    return {"t": float(t), "state": state, **decision.to_json()}


def decisions_file(member: int = 0) -> str:
    """The decisions file of fleet member ``member`` (docs/fleet.md): ``decisions.jsonl``
    member 0's (one ownship's, as the README has it), ``decisions-j.jsonl`` member j's, each
    line as decisions.jsonl's, from the member's own view (its state as ``ownship``)."""
    return "decisions.jsonl" if member == 0 else f"decisions-{member}.jsonl"


def _members(run_dir: Path) -> int:
    """How many members the run in RUN_DIR flew: its summary.json's ``fleet`` entries (1
    without a fleet), so a file another run left in the folder is not taken for a member; by
    the decisions files there are when the summary is missing or unreadable (a run cut short)."""
    try:
        summary = json.loads((run_dir / "summary.json").read_text(encoding="utf-8"))
        return max(1, len(summary.get("fleet") or []))
    except (OSError, ValueError, AttributeError, TypeError):
        members = 1
        while (run_dir / decisions_file(members)).is_file():
            members += 1
        return members


def read_decisions(run_dir: Path, member: int = 0) -> list[dict[str, Any]]:
    """The records of RUN_DIR/decisions.jsonl (a fleet's member ``member``:
    decisions-j.jsonl); UserError naming the problem otherwise."""
    run_dir = Path(run_dir)
    if not run_dir.is_dir():
        raise UserError(f"{run_dir}: no such run folder (give the --out folder of `uavxai run`).")
    if member < 0:
        raise UserError(f"--member {member}: a fleet's members are numbered from 0.")
    path = run_dir / decisions_file(member)
    members = _members(run_dir)
    if member >= members:  # the run has no such member: say which it has
        flew = "flew one UAV, member 0" if members == 1 else f"flew members 0 to {members - 1}"
        raise UserError(
            f"--member {member}: the run in {run_dir} has no member {member}; it {flew} "
            "(a fleet's member j writes decisions-j.jsonl)."
        )
    if member > 0 and not path.is_file():  # the run has it, but its file is gone
        raise UserError(
            f"--member {member}: {path} is missing, though the run flew member {member} "
            f"(members 0 to {members - 1}); was it moved or deleted?"
        )
    if not path.is_file():
        raise UserError(f"{path}: not found; is {run_dir} the output folder of `uavxai run`?")
    records = []
    with path.open(encoding="utf-8") as f:
        for number, line in enumerate(f, start=1):
            if not line.strip():
                continue
            try:
                record = json.loads(line)
            except json.JSONDecodeError as exc:
                raise UserError(
                    f"{path}, line {number}: not valid JSON ({exc.msg}); the file is damaged."
                ) from None
            if not isinstance(record, dict) or "action" not in record:
                raise UserError(
                    f"{path}, line {number}: not a decision record (an object with `action`, "
                    "`children`, `explanation`, ...)."
                )
            records.append(record)
    return records


def explain_command(run_dir: Path, decision: int | None = None, member: int = 0) -> str:
    """The text `uavxai explain RUN_DIR [--decision N] [--member J]` prints.

    ``decision`` indexes the decisions from 0 (negative: from the end); None gives an overview.
    ``member``: a fleet member's decisions (0: the run's ownship, decisions.jsonl).
    """
    records = read_decisions(Path(run_dir), member)
    if not records:
        return f"{Path(run_dir) / decisions_file(member)}: no decisions were recorded."
    if decision is None:
        return render_overview(records)
    n = len(records)
    if not -n <= decision < n:
        raise UserError(
            f"--decision {decision}: out of range; this run has {n} decisions, so N must be "
            f"between 0 and {n - 1} (or -{n} to -1 from the end)."
        )
    index = decision % n
    return render_record(records[index], index, n)


def render_record(record: dict[str, Any], index: int, total: int) -> str:
    """A readable multi-line account of one decisions.jsonl record."""
    act = record.get("action", {})
    planner = record.get("planner") or "planner"
    t = record.get("t")
    head = f"Decision {index} of {total}"
    if isinstance(t, int | float):
        head += f" at t = {t:.1f} s"
    head += f" ({planner}, {_num(record.get('ms'), '.1f')} ms)"
    lines = [head]
    own = (record.get("state") or {}).get("ownship")
    if isinstance(own, dict):
        lines.append(
            f"  ownship: x {_num(own.get('x'))} m, y {_num(own.get('y'))} m, "
            f"h {_num(own.get('h'))} m, {_num(own.get('speed'), '.1f')} m/s, "
            f"heading {_deg(own.get('heading'))}, bank command {_deg(own.get('bank'))}"
        )
    name = act.get("name") or "action"
    lines.append(
        f"  chose:   {name} -> bank command {_deg(act.get('bank_cmd_rad'))}, "
        f"{_num(act.get('accel_mps2'), '+.1f')} m/s^2"
    )
    if record.get("explanation"):
        lines.append(f"  why:     {record['explanation']}")
    if record.get("counterfactual"):
        lines.append(f"  why not: {record['counterfactual'].removeprefix('why not ')}")
    sep = record.get("predicted_min_separation_m")
    if sep is not None:
        lines.append(f"  predicted minimum separation over the next decision period: {sep:.0f} m")
    children = record.get("children") or []
    if children:
        total_visits = sum(int(c.get("visits") or 0) for c in children) or 1
        lines.append("  root actions:")
        lines.append(
            f"    {'action':<26}{'visits':>7}{'share':>7}{'Q':>7}{'min sep':>10}"
            f"  {'intruder':<12}{'in':>7}  line ends"
        )
        chosen_index = act.get("index")
        for c in children:
            a = c.get("action", {})
            mark = "*" if a.get("index") == chosen_index else " "
            visits = int(c.get("visits") or 0)
            sep, when = c.get("predicted_min_separation_m"), c.get("time_to_closest_s")
            who = c.get("closest_intruder")
            cells = [
                f"{a.get('name', '?'):<26}",
                f"{visits:>7}",
                f"{100 * visits / total_visits:>6.0f}%",
                f"{_num(c.get('q'), '.3f'):>7}",
                f"{_num(sep) + ' m' if sep is not None else 'clear':>10}",
                f"  {who if who is not None else '-':<12}",
                f"{_num(when, '.1f') + ' s' if when is not None else '-':>7}",
                f"  {c.get('outcome') or 'open'}{_TRAPPED if c.get('trapped') else ''}"
                f"{_PINNED.format(_name(c['pinned'][0][0])) if c.get('pinned') else ''}",
            ]
            lines.append(f"  {mark} " + "".join(cells))
    return "\n".join(lines)


# decisions.jsonl's `trapped` (planners that weigh the walls): the line stays in the area to its
# end but can no longer turn away from an edge there, so the cornered rule counts it as leaving.
_TRAPPED = ", cannot turn from the edge"
# decisions.jsonl's `pinned` (planners that weigh pinning): the line's open end lies under (or
# over) a track with no room to let it pass below (above) before the floor (the ceiling).
_PINNED = ", pinned by {}"


def render_overview(records: Sequence[dict[str, Any]]) -> str:
    """Count, how many decisions steered away from something, and the tightest one."""
    n = len(records)
    avoid = [i for i, r in enumerate(records) if _record_avoids(r)]
    seps = [
        (r["predicted_min_separation_m"], i)
        for i, r in enumerate(records)
        if isinstance(r.get("predicted_min_separation_m"), int | float)
    ]
    ms = [r["ms"] for r in records if isinstance(r.get("ms"), int | float)]
    lines = [f"{n} decisions; {len(avoid)} steered away from a predicted conflict."]
    if ms:
        lines.append(f"Planner time: mean {sum(ms) / len(ms):.1f} ms, max {max(ms):.1f} ms.")
    if seps:
        sep, i = min(seps)
        lines.append(
            f"Tightest: decision {i}, predicted {sep:.0f} m over the next period: "
            f"{records[i].get('explanation', '')}"
        )
    for i in avoid[:10]:
        lines.append(f"  [{i}] {records[i].get('explanation', '')}")
    if len(avoid) > 10:
        lines.append(f"  ... and {len(avoid) - 10} more")
    lines.append("Show one in full with `uavxai explain RUN_DIR --decision N`.")
    return "\n".join(lines)


def _record_avoids(record: dict[str, Any]) -> bool:
    d_min = record.get("d_min_m") or 50.0
    index = (record.get("action") or {}).get("index")
    children = []
    for c in record.get("children") or []:
        sep = c.get("predicted_min_separation_m")
        action = (c.get("action") or {}).get("index", -1)
        flies = _INDEX_OF.get(c.get("flies"), action)
        children.append(
            ChildStats(
                action=action,
                bank_cmd_rad=0.0,
                accel_mps2=0.0,
                visits=int(c.get("visits") or 0),
                q=float(c.get("q") or 0.0),
                predicted_min_separation_m=math.inf if sep is None else float(sep),
                closest_intruder=c.get("closest_intruder"),
                outcome=c.get("outcome") or "",
                effect=None if flies == action else flies,
            )
        )
    return index is not None and is_avoidance(children, index, d_min)


_INDEX_OF = {a.name: a.index for a in ACTIONS}  # decisions.jsonl names actions


def _num(x: Any, fmt: str = ".0f") -> str:
    return format(x, fmt) if isinstance(x, int | float) else "?"


def _deg(x: Any) -> str:
    return f"{math.degrees(x):.0f} deg" if isinstance(x, int | float) else "?"


set_narrator(explain)  # every Decision's words come from here


def operator_aim(
    asked: str, kind: str, ago_s: float, mode: str, own_h: float, own_speed: float
) -> str:
    """How a decision under an operator's aim opens: what was asked, when, in which mode, and
    where the aircraft is against it ("the operator asked for 60 m 14 s ago (AUTO), at
    118 m now"); the decision's own sentence then says why it flies as it does."""
    now = ""
    if kind == "altitude":
        now = f", at {own_h:.0f} m now"
    elif kind == "speed":
        now = f", at {own_speed:.1f} m/s now"
    return f"the operator asked for {asked} {ago_s:.0f} s ago ({mode}){now}; avoidance on"
