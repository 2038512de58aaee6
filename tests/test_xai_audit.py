"""An audit of the explanations (issue 14, "Explanations must be true to the tree").

Recorded runs with real avoidance (dense manoeuvring traffic with a collision, a crossing
swarm, a head-on; MCTS and the exhaustive search; one JSBSim run through `uavxai run`) are
flown, and every sentence and counterfactual in their decisions.jsonl is parsed with one
regular expression per claim type. Every claim is checked against what it is about: the
decision's record, its search tree (each option's line re-flown here, its separations
solved here, apart from the planner's code), the tree graph and plan label the viewer
draws, and the flight in trajectory.csv. Text a claim pattern does not account for fails
the audit too, so a new kind of sentence cannot slip past unchecked.
"""

from __future__ import annotations

import json
import math
import re
from collections import Counter
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np
import pytest

from uavxai.avoidance.mcts import predict_levels
from uavxai.avoidance.model import GOAL, NONE, OUT_OF_BOUNDS, EncounterModel
from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import Intruder, Ownship, PlannerConfig
from uavxai.recording.recorder import _plan_label
from uavxai.recording.tree_graph import CHOSEN_COLOR, tree_graph
from uavxai.scenario import Scenario, load_scenario
from uavxai.sim.build import fly
from uavxai.sim.episode import Observer
from uavxai.sim.mission import CONFLICT_FACTOR, ON_ORBIT_SHARE, MissionConfig, orbit_clearance
from uavxai.sim.observers import DecisionsJSONL, TrajectoryCSV, Trust
from uavxai.sim.spec import episode_goal, episode_spec
from uavxai.vocabulary import ACTIONS, HOLD
from uavxai.xai.explain import explain_command

SCENARIOS = Path(__file__).resolve().parents[1] / "scenarios"
SPEED_SHARE = 0.1  # a speed change below this share of what is commanded is none (docs)
BANK_EPS = 1e-6  # rad: the bank command comes back from the autopilot at float32 precision


# ------------------------------------------------------------------------------ flying
class _Keep(Observer):
    """The planner's Decision objects, search trees included (the files do not hold them)."""

    def __init__(self) -> None:
        self.decisions: list = []
        self.goals: list = []  # where the planner steered (a mission's moves with its phase)

    def on_decision(self, ep, event) -> None:
        self.decisions.append(event.decision)
        self.goals.append(tuple(ep.aim()))


@dataclass
class Run:
    folder: Path
    config: PlannerConfig
    goal: tuple[float, float, float]
    records: list[dict]
    decisions: list  # Decision objects (None: only the files, e.g. a `uavxai run`)
    summary: dict
    contexts: list = field(default_factory=list)  # per decision, as the audit read it
    max_steps: int = 0  # the episode's own limit (0: the planner's, a transit-only episode)
    mission: object = None  # uavxai.sim.mission.MissionConfig of a mission, else None
    goals: list = field(default_factory=list)  # per decision (empty: ``goal`` throughout)

    @property
    def steps_limit(self) -> int:
        return self.max_steps or self.config.max_steps


def fly_recorded(
    sc: Scenario, planner_name: str, folder: Path, dynamics: str = "kinematic", mission=None
) -> Run:
    """Fly ``sc`` (kinematic unless told), writing the files `uavxai run` writes; with a
    ``mission`` (MissionConfig) the whole mission, to its station."""
    folder.mkdir(parents=True, exist_ok=True)
    planner = make_planner(planner_name, PlannerConfig.from_scenario(sc))
    # the run's episode: the scenario's goal and intruders at its seed, or the mission's station
    spec = episode_spec(sc, dynamics=dynamics, goal=mission and mission.station, mission=mission)
    goal = spec.goal
    keep = _Keep()
    observers = [
        Trust(),
        TrajectoryCSV(folder / "trajectory.csv"),
        DecisionsJSONL(folder / "decisions.jsonl"),
        keep,
    ]
    result = fly(spec, planner, observers=observers)
    (folder / "summary.json").write_text(json.dumps(result.summary))
    records = [json.loads(line) for line in (folder / "decisions.jsonl").open()]
    run = Run(folder, planner.config, tuple(goal), records, keep.decisions, result.summary)
    run.max_steps, run.mission, run.goals = spec.max_steps, mission, keep.goals
    return run


def scenario(name: str, **changes) -> Scenario:
    """A shipped scenario with ``changes`` merged into its sections."""
    sc = load_scenario(SCENARIOS / f"{name}.yaml")
    data = sc.model_dump()
    for section, values in changes.items():
        if isinstance(values, dict):
            for key, value in values.items():
                if isinstance(value, dict):
                    data[section][key].update(value)
                else:
                    data[section][key] = value
        else:
            data[section] = values
    return Scenario.model_validate(data)


# ------------------------------------------------------------------- lines, re-measured
@dataclass
class Line:
    """What the audit finds an option's line predicts (its own geometry, not the planner's)."""

    min_sep: float = math.inf
    closest: object = None
    meets: tuple | None = None  # (intruder id, time, miss, needed)
    end: int = NONE  # the line's terminal code
    horizon: float = 0.0
    unsure: tuple = ()  # (id, closest approach less its margin there), closer than min_sep


def line_truths(decision, record: dict, cfg: PlannerConfig, goal) -> dict[int, Line]:
    """Every root option's line (the tree's best line below it) re-flown against the
    intruders the record says the planner saw, predicted as the planner predicts them."""
    model = EncounterModel(cfg)
    intruders = [Intruder(**i) for i in record["state"]["intruders"]]
    tracks = predict_levels(model, intruders, cfg.depth, cfg.action_hold_s)
    tree = decision.tree
    out = {}
    for child in tree.children_of(0):
        line = tree.best_line(int(child))
        out[int(tree.action[child])] = _line(tree, line, model, tracks, intruders, cfg, goal)
    return out


def _line(tree, line, model, tracks, intruders, cfg, goal) -> Line:
    hold, ids = cfg.action_hold_s, [i.id for i in intruders]
    best = np.full(len(ids), math.inf)
    best_t = np.full(len(ids), math.nan)
    best_margin = np.zeros(len(ids))
    truth = Line()
    for node in line:
        level = int(tree.depth[node]) - 1
        track = tracks[level]
        seg = model.fly(
            tree.state[tree.parent[node]][None],
            np.array([tree.action[node]]),
            np.asarray(goal, dtype=float),
            hold,
            track,
            cull=False,
            exact=True,
        )
        own = seg.samples[0]
        n = own.shape[0] - 1
        dt = hold / n
        truth.end = int(tree.terminal[node])
        keep = n
        if truth.end in (GOAL, OUT_OF_BOUNDS):  # the line stops at the end of that sub-step
            keep = int(round(float(seg.t_event[0]) / dt)) + 1
        truth.horizon = level * hold + keep * dt
        if ids:
            dist, frac = _closest_on_substeps(own, track.pos)
            t = level * hold + (np.arange(n)[:, None] + frac) * dt
            k = np.argmin(dist[:keep], axis=0)
            cols = np.arange(len(ids))
            closer = dist[k, cols] < best
            best[closer], best_t[closer] = dist[k, cols][closer], t[k, cols][closer]
            if track.margin is not None:
                best_margin[closer] = track.margin[k + 1, cols][closer]
            need = cfg.d_min_m + (0.0 if track.margin is None else track.margin[1:])
            need = np.broadcast_to(need, dist.shape)
            inside = np.argwhere(dist[:keep] < need[:keep])  # nothing counts past the end
            if truth.meets is None and inside.size:
                k = int(inside[0, 0])
                j = int(np.argmax(need[k] - dist[k]))
                truth.meets = (ids[j], level * hold + k * dt, j, float(need[k, j]))
        if truth.end != NONE:
            break
    if ids:
        j = int(np.argmin(best))
        truth.min_sep, truth.closest = float(best[j]), ids[j]
        could = np.maximum(best - best_margin, 0.0)
        truth.unsure = tuple((ids[i], float(could[i])) for i in np.argsort(could, kind="stable")
                             if i != j and could[i] < best[j])  # fmt: skip
    if truth.meets is not None:
        who, when, j, need = truth.meets
        truth.meets = (who, when, float(best[j]), need)
    return truth


def _closest_on_substeps(own: np.ndarray, others: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n, N) closest distance within each sub-step (both moving straight) and where."""
    r0 = own[:-1, None, :] - others[:-1]
    dr = (own[1:, None, :] - others[1:]) - r0
    s = np.clip(-(r0 * dr).sum(-1) / np.maximum((dr * dr).sum(-1), 1e-12), 0.0, 1.0)
    return np.linalg.norm(r0 + s[..., None] * dr, axis=-1), s


# ------------------------------------------------------------------------ the flight
def flight(folder: Path) -> tuple[np.ndarray, list[dict[str, np.ndarray]]]:
    """Sample times and, per sample, each aircraft's position (ownship first)."""
    times, samples = [], []
    with (folder / "trajectory.csv").open() as f:
        next(f)
        for row in f:
            t, ident, x, y, h = row.split(",")[:5]
            if not times or times[-1] != t:
                times.append(t)
                samples.append({})
            samples[-1][ident] = np.array([float(x), float(y), float(h)])
    return np.array([float(t) for t in times]), samples


def flown_min(
    times: np.ndarray, samples: list, t0: float, t1: float, only: str | None = None
) -> float:
    """The smallest ownship-intruder distance flown from ``t0`` until the first sample at or
    after ``t1`` (linear between samples; an aircraft new in a sample counts from there);
    ``only``: to that intruder (its number) alone."""
    out = math.inf
    first = int(np.searchsorted(times, t0 + 1e-9))
    for i in range(max(first, 1), len(times)):
        prev, now = samples[i - 1], samples[i]
        own0, own1 = prev["ownship"], now["ownship"]
        for ident, p1 in now.items():
            if ident == "ownship" or (only is not None and not _name_ok(ident, only)):
                continue
            p0 = prev.get(ident) if len(prev) == len(now) else None
            if p0 is None:
                out = min(out, float(np.linalg.norm(own1 - p1)))
            else:
                d, _ = _closest_on_substeps(np.stack([own0, own1]), np.stack([p0, p1])[:, None])
                out = min(out, float(d[0, 0]))
        if times[i] >= t1 - 1e-9:
            break
    return out


# ------------------------------------------------------------------------- the claims
OPT = "|".join(sorted((re.escape(a.phrase) for a in ACTIONS), key=len, reverse=True))
VERB = "|".join(sorted({re.escape(a.verb) for a in ACTIONS}, key=len, reverse=True))
LIMITS = (
    "the bank command and the speed are at their limits|the bank command is at its limit"
    "|the speed is at its limit|the vertical command is at its limit"
)
MEETS = (
    r"meets intruder (?P<k>[^\s;,()]+) in (?P<t>\d+\.\d) s "
    r"\(predicted miss (?P<miss>\d+) m, (?P<need>\d+) m needed\)"
)
Q = r"\d+\.\d{3}"
RISK = r"(?:; (?P<risk>\d+)% of its simulations collide)?"
WHY = (
    r"(?P<why>this one had more simulations \((?P<wa>\d+) against (?P<wb>\d+)\)"
    r"|as many simulations \((?P<wn>\d+) each\): a higher Q beyond 3 decimals"
    r"|as many simulations \((?P<wm>\d+) each\) and Q: the first in action order"
    r"|a higher Q beyond 3 decimals decided|the tie goes to the first in action order)"
)
KEEPS = r"is predicted to keep (?P<n>\d+) m from intruder (?P<k>[^\s;,()]+?)"
ENDS = r"ends out of bounds|ends at the time-out|ends timeout"
GOAL_TAIL = rf"(?:(?P<goal> and reaches the goal)|(?: and (?P<end>{ENDS})(?P<too2> too)?))?(?=;|$)"
ORBIT_WHERE = (
    r"^on station: (?:orbiting \((?P<x>-?\d+), (?P<y>-?\d+)\) at (?P<r>\d+) m radius, "
    r"(?P<h>-?\d+) m height|joining the orbit about \((?P<x2>-?\d+), (?P<y2>-?\d+)\), "
    r"(?:(?P<d>\d+) m from its centre, radius (?P<r2>\d+) m"
    r"|(?P<off>\d+) m (?P<side>outside|inside) its (?P<r3>\d+) m radius))"
)
ORBIT_PASS = (
    r"; intruder (?P<k>[^\s;,()]+) predicted to pass (?:the orbit ahead|(?P<old>it)) at "
    r"(?P<n>\d+) m in (?P<t>\d+) s(?P<cond> if it holds its present turn \(2-sigma track error "
    r"taken off; the orbit is left below (?P<lim>\d+) m\))?"
)
PHRASE = {a.phrase: a.index for a in ACTIONS}

# (claim type, where, pattern), matched in this order; each match is blanked before the next
# pattern runs, and what is left must be punctuation only.
CLAIMS = [
    ("verb", "s",
     rf"^(?P<verb>{VERB})(?: \((?P<asked>{OPT}) changes nothing: (?P<lim>{LIMITS})\))?:"),
    ("why not names the runner-up", "c",
     rf"^why not (?P<opt>{OPT})(?: \(flies as (?P<as>{OPT}): (?P<lim>{LIMITS})\))?:"),
    ("cornered: chose by the stated rule", "s",
     r"every option meets an intruder, so it took the one that "
     r"(?P<stay>stays in the flight area \(an option that "
     r"(?:meets later|passes wider or meets later) "
     r"(?P<out>leaves it|can no longer stay in it)\) and )?meets its intruder latest"
     r"(?: \(in (?P<t>\d+\.\d) s, the next in (?P<t2>\d+\.\d) s\)"
     r"| \(in (?P<t3>\d+\.\d) s, as another does\) and passes it widest "
     rf"\((?P<m>\d+\.\d) m against (?P<m2>\d+\.\d) m\)| and passes it widest, tied: {WHY})?"),
    ("cornered: chose by the widest rule", "s",
     r"every option meets an intruder, so it took the one that "
     r"(?P<stay>stays in the flight area \(an option that "
     r"(?:meets later|passes wider or meets later) "
     r"(?P<out>leaves it|can no longer stay in it)\) and )?passes the traffic "
     r"(?:widest(?P<among> of the options that stay in the area)? \((?P<w>\d+\.\d+) m from the "
     r"nearest intruder against (?P<w2>\d+\.\d+) m\)"
     r"|at (?P<w0>\d+\.\d) m from the nearest intruder"
     r"|as wide as another \((?:(?P<cap>\d+) m or more|(?P<weq>\d+\.\d) m)\) and meets its "
     r"intruder (?:latest \(in (?P<t>\d+\.\d) s, the next in (?P<t2>\d+\.\d) s\)"
     r"|as late, passing wider \((?P<s>\d+\.\d+) m against (?P<s2>\d+\.\d+) m\)"
     rf"|as late, tied: {WHY}))"),
    ("orbit: where", "o", ORBIT_WHERE),
    ("orbit: intruder passes", "o", ORBIT_PASS),
    ("why not: a collision", "c", rf"(?P<opt>it) {MEETS}, a predicted collision"),
    ("why not: inside the margin", "c",
     rf"(?P<opt>it) {MEETS}, inside the (?P<mg>\d+) m margin kept beyond the (?P<dm>\d+) m "
     r"collision distance for what that intruder may do, which the search counts as a collision"),
    ("every option ends", "s", rf"every option (?P<how>{ENDS})"),
    ("why not: both conflict", "c", rf"(?P<opt>it) {MEETS} too;"),
    ("cornered: why not, widest", "c",
     rf"(?P<opt>it) {MEETS}, (?P<how>and comes nearer the traffic \((?P<n1>\d+\.\d+) m from "
     r"the nearest intruder against (?P<n2>\d+\.\d+) m\)|as soon and nearer the traffic)"),
    ("cornered: why not", "c",
     rf"(?P<opt>it) {MEETS}, (?P<how>sooner|as soon and closer|the same; {WHY})"),
    ("meets k at N m", "sc", rf"(?P<opt>{OPT}|it) {MEETS}"),
    ("every option conflicts", "s", r"every option meets an intruder"),
    ("keeps N m from k", "sc", rf"(?P<opt>{OPT}|it) {KEEPS}{GOAL_TAIL}"),
    ("keeps: less sure of", "sc",
     r"less sure of (?P<list>intruder [^\s;,()]+ \(could pass at \d+ m\)"
     r"(?:, intruder [^\s;,()]+ \(could pass at \d+ m\))*)(?: and (?P<more>\d+) more)?"),
    ("keeps clear", "sc", rf"(?P<opt>{OPT}|it) keeps clear of every known intruder{GOAL_TAIL}"),
    ("line ends", "sc", rf"(?P<opt>{OPT}|its best line) (?P<how>{ENDS})(?P<too> too)?"),
    ("Q lower", "s", rf"(?P<opt>{OPT}) scores lower \(Q (?P<a>{Q}) against (?P<b>{Q}){RISK}\)"),
    ("Q higher, fewer simulations", "sc",
     rf"(?P<opt>{OPT}) has the higher Q \((?P<a>{Q}) against (?P<b>{Q}){RISK}\) but fewer "
     r"simulations \((?P<va>\d+) against (?P<vb>\d+)\)"
     rf"|a higher Q \((?P<a2>{Q}) against (?P<b2>{Q}){RISK.replace('risk', 'risk2')}\) but "
     r"fewer simulations \((?P<va2>\d+) against (?P<vb2>\d+)\)"),
    ("Q tie says what decided", "sc",
     rf"(?:(?P<opt>{OPT}) is as good \(Q (?P<a>{Q})\)|as good \(Q (?P<a2>{Q}) both\)), {WHY}"),
    ("Q comparison", "c",
     rf"Q (?P<a>{Q}) against (?P<b>{Q})"
     rf"(?: \((?P<va>\d+) simulations against (?P<vb>\d+){RISK}\))?"),
    ("support", "s",
     r"(?:(?P<p>\d+)% of simulations agree|(?P<all>every action sequence to the search depth "
     r"scored)|the best of every action sequence to the search depth)$"),
]  # fmt: skip
_COMPILED = [(name, where, re.compile(p)) for name, where, p in CLAIMS]


@dataclass
class Audit:
    """Claims checked and, per kind, how many were false (the record or the tree contradict
    them), misleading (true to the letter, but said as a reason that was none, or leaving
    the chosen line's own end unsaid) and contradicted by the flight (a prediction the
    aircraft then flew more than ``FLIGHT_TOLERANCE_M`` short of: the words say
    "predicted", so it is no false claim, but it is counted and bounded)."""

    checked: Counter = field(default_factory=Counter)
    false: Counter = field(default_factory=Counter)
    misleading: Counter = field(default_factory=Counter)
    contradicted: Counter = field(default_factory=Counter)
    failures: list[str] = field(default_factory=list)
    info: Counter = field(default_factory=Counter)

    def claim(self, kind: str, ok: bool, where: str) -> None:
        self.checked[kind] += 1
        if not ok:
            self._count(self.false, kind, where)

    def mislead(self, kind: str, where: str) -> None:
        self._count(self.misleading, kind, where)

    def flown(self, kind: str, held: bool, where: str) -> None:
        """A prediction set against the flight: counted when the flight contradicts it."""
        self.info[f"flight: {kind}"] += 1
        if not held:
            self._count(self.contradicted, kind, where)

    def _count(self, counter: Counter, kind: str, where: str) -> None:
        counter[kind] += 1
        if len(self.failures) < 40:
            self.failures.append(f"{kind}: {where}")

    def totals(self) -> dict[str, int]:
        return {
            "claims": sum(self.checked.values()),
            "false": sum(self.false.values()),
            "misleading": sum(self.misleading.values()),
            "flown": sum(v for k, v in self.info.items() if k.startswith("flight: ")),
            "contradicted": sum(self.contradicted.values()),
        }

    def table(self) -> str:
        rows = [f"{'claim':<44}{'checked':>9}{'false':>7}{'mislead':>9}{'flown x':>9}"]
        kinds = sorted(set(self.checked) | set(self.contradicted) | set(self.misleading))
        for kind in kinds:
            rows.append(f"{kind:<44}{self.checked[kind]:>9}{self.false[kind]:>7}"
                        f"{self.misleading[kind]:>9}{self.contradicted[kind]:>9}")  # fmt: skip
        t = self.totals()
        rows.append(f"{'total':<44}{t['claims']:>9}{t['false']:>7}{t['misleading']:>9}"
                    f"{t['contradicted']:>9}  ({t['flown']} set against flight)")  # fmt: skip
        return "\n".join(rows)


FLIGHT_TOLERANCE_M = 10.0  # a prediction flown more than this short of is contradicted


@dataclass
class Ctx:
    """One decision as the checks see it."""

    record: dict
    cfg: PlannerConfig
    kids: dict[int, dict]
    chosen: dict
    flies: dict[int, int]  # the audit's own reading of the clamped commands
    lines: dict[int, Line] | None  # None: no tree (a run known only from its files)
    decision: object = None
    runner: dict | None = None
    text: str = ""
    audit: Audit | None = None
    label: str = ""
    run: Run | None = None
    flight: tuple = ()  # (times, samples) of the run's trajectory
    index: int = 0  # the decision's step in its episode
    said_chosen_end: bool = False  # the words said how the chosen line ends

    def q(self, c: dict) -> float:
        return float(c["q"])

    @property
    def sampled(self) -> bool:
        return not self.record["planner"].startswith("exhaustive")

    def conflicts(self, c: dict) -> bool:
        """From the re-flown line when there is a tree, else from the record."""
        if self.lines is not None:
            return self.lines[c["action"]["index"]].meets is not None
        return c["meets"] is not None


def flies_of(record: dict, child: dict, cfg: PlannerConfig) -> int:
    """The manoeuvre ``child`` flies, read from its recorded command and the ownship's state."""
    own, a = record["state"]["ownship"], ACTIONS[child["action"]["index"]]
    step = child["action"]["bank_cmd_rad"] - own["bank"]
    bank = int(np.sign(step)) if abs(step) > BANK_EPS else 0
    commanded = cfg.accel_mps2 * cfg.action_hold_s
    v = own["speed"]
    band = own.get("speed_band") or cfg.speed_mps  # the speeds this decision might fly
    lo, hi = min(band[0], v), max(band[1], v)
    change = min(max(v + a.accel * commanded, lo), hi) - v
    accel = a.accel if commanded > 0 and abs(change) >= SPEED_SHARE * commanded else 0
    vertical = own.get("vertical", 0)
    climb = 0 if min(max(vertical + a.climb, -1), 1) == vertical else a.climb
    return next(b.index for b in ACTIONS if (b.bank, b.accel, b.climb) == (bank, accel, climb))


def _subject(ctx: Ctx, m: re.Match) -> dict | None:
    opt = m.groupdict().get("opt")
    if opt in ("it", "its best line"):
        return ctx.runner
    if opt is None:
        return ctx.runner if ctx.text == "c" else ctx.chosen
    return ctx.kids.get(PHRASE[opt])


def _name_ok(intruder_id, said: str) -> bool:
    return str(intruder_id).removeprefix("intruder-") == said.removeprefix("intruder-")


def _near(value: float, said: str, half_unit: float) -> bool:
    return abs(value - float(said)) <= half_unit + 1e-6


def _limits_ok(asked: int, flown: int, said: str) -> bool:
    a, f = ACTIONS[asked], ACTIONS[flown]
    differs = (
        ("bank", a.bank != f.bank), ("speed", a.accel != f.accel), ("vertical", a.climb != f.climb)
    )  # fmt: skip
    parts = [p for p, differ in differs if differ]
    expected = {
        ("bank",): "the bank command is at its limit",
        ("speed",): "the speed is at its limit",
        ("bank", "speed"): "the bank command and the speed are at their limits",
        ("vertical",): "the vertical command is at its limit",
    }
    return expected.get(tuple(parts)) == said


def check_verb(ctx: Ctx, m: re.Match) -> bool:
    index = ctx.chosen["action"]["index"]
    flown = ctx.flies[index]
    if m["verb"] != ACTIONS[flown].verb:
        return False
    if m["asked"] is None:
        return flown == index
    return PHRASE[m["asked"]] == index and flown != index and _limits_ok(index, flown, m["lim"])


def check_runner(ctx: Ctx, m: re.Match) -> bool:
    runner, chosen = ctx.runner, ctx.chosen
    if runner is None:
        return False
    r, c = runner["action"]["index"], chosen["action"]["index"]
    if ctx.flies[r] == ctx.flies[c]:  # the same manoeuvre is no alternative
        return False
    if m["as"] is None and ctx.flies[r] != r:
        return False
    if m["as"] is not None and not (
        PHRASE[m["as"]] == ctx.flies[r] and _limits_ok(r, ctx.flies[r], m["lim"])
    ):
        return False
    others = [k for k in ctx.kids.values() if ctx.flies[k["action"]["index"]] != ctx.flies[c]]
    best = max(others, key=lambda k: _rank(ctx, k))
    return best is runner


def _rank(ctx: Ctx, k: dict) -> tuple:
    """How the planner ranks options: by the cornered rule when it said it used it, else as the
    search does (simulations, Q, action order)."""
    if ctx.record.get("cornered"):
        line = ctx.lines[k["action"]["index"]] if ctx.lines else None
        meets = line.meets if line else k["meets"] and tuple(k["meets"].values())
        when, miss = (round(meets[1], 6), meets[2]) if meets else (-math.inf, -math.inf)
        # the planner's own order (lines.cornered_key): staying in, then the rule's terms
        # (widest: width, meeting, miss; latest: meeting, the met intruder's miss), then the
        # search's (the best-value backup ranks by Q first)
        search = (k["q"], k["visits"]) if ctx.cfg.backup == "best" else (k["visits"], k["q"])
        if _widest(ctx):
            terms: tuple = (_width(ctx, k), when, _sep(ctx, k))
        else:
            terms = (when, miss)
        return (not _leaves(k), *terms, *search, -k["action"]["index"])
    return (k["visits"], k["q"], -k["action"]["index"])


def _widest(ctx: Ctx) -> bool:
    """Did a cornered decision choose by `avoidance.mcts.cornered_rule: widest`?"""
    return ctx.record.get("cornered_rule") == "widest"


def _sep(ctx: Ctx, k: dict) -> float:
    """The option's predicted closest approach to any intruder: the audit's own re-flown line
    when there is a tree (the record must hold the same number, or the claim is false: nan
    then fails every comparison), else the record's."""
    v = k["predicted_min_separation_m"]
    recorded = math.inf if v is None else float(v)
    if ctx.lines is None:
        return recorded
    own = ctx.lines[k["action"]["index"]].min_sep
    return own if math.isclose(recorded, own, abs_tol=0.01) else math.nan


def _leaves(k: dict) -> bool:
    return k["outcome"] == "out_of_bounds" or bool(k.get("trapped"))


def _width(ctx: Ctx, k: dict) -> float:
    """The widest rule's pass width: the closest approach up to twice d_min (the audit's own
    reading of the rule, docs/scenario.md)."""
    return min(_sep(ctx, k), 2.0 * ctx.record["d_min_m"])


def _stay_head_ok(ctx: Ctx, m: re.Match) -> bool:
    """The "stays in the flight area (an option that ... leaves it) and" head is said exactly
    when the chosen line stays in and an option that leaves is better by the rule's own terms
    (latest: meets later or not at all; widest: wider, then later, then wider uncapped)."""
    kids, chosen = list(ctx.kids.values()), ctx.chosen
    if _widest(ctx):
        def terms(k):  # the rule's own terms: width, meeting, miss
            return _rank(ctx, k)[1:4]
        better = [k for k in kids if _leaves(k) and terms(k) > terms(chosen)]
    else:
        mine = _meeting(ctx, chosen)
        better = [k for k in kids if _leaves(k) and (
            _meeting(ctx, k) is None or mine is None or _meeting(ctx, k)[1] > mine[1])]
    said = m["stay"] is not None
    if said != (not _leaves(chosen) and bool(better)):
        return False
    if not said:
        return True
    how = "passes wider or meets later" if _widest(ctx) else "meets later"
    out = any(not k.get("trapped") for k in better)
    return how in m["stay"] and m["out"] == ("leaves it" if out else "can no longer stay in it")


def check_cornered_widest(ctx: Ctx, m: re.Match) -> bool:
    kids = list(ctx.kids.values())
    if not (ctx.record.get("cornered") and _widest(ctx) and all(ctx.conflicts(k) for k in kids)):
        return False
    if max(kids, key=lambda k: _rank(ctx, k)) is not ctx.chosen:  # the rule really chose it
        return False
    if not _stay_head_ok(ctx, m) or (m["among"] is not None) != (m["stay"] is not None):
        return False
    c = ctx.chosen["action"]["index"]
    peers = [k for k in kids if ctx.flies[k["action"]["index"]] != ctx.flies[c]
             and _leaves(k) == _leaves(ctx.chosen)]  # fmt: skip
    mine = _sep(ctx, ctx.chosen)
    if m["w0"] is not None:
        return not peers and _near(mine, m["w0"], 0.05)
    best = max(peers, key=lambda k: _rank(ctx, k)) if peers else None
    if best is None:
        return False
    theirs = _sep(ctx, best)
    if m["w"] is not None:
        return (_near(mine, m["w"], 0.05) and _near(theirs, m["w2"], 0.05)
                and _width(ctx, ctx.chosen) > _width(ctx, best))  # fmt: skip
    if _width(ctx, ctx.chosen) != _width(ctx, best):
        return False
    if m["cap"] is not None and not (
        float(m["cap"]) == 2.0 * ctx.record["d_min_m"] and mine >= float(m["cap"])
    ):
        return False
    if m["weq"] is not None and not _near(mine, m["weq"], 0.05):
        return False
    t_mine, t_theirs = _meeting(ctx, ctx.chosen)[1], _meeting(ctx, best)[1]
    if m["t"] is not None:
        return (_near(t_mine, m["t"], 0.05) and _near(t_theirs, m["t2"], 0.05)
                and t_mine > t_theirs)  # fmt: skip
    if abs(t_mine - t_theirs) > 1e-9:
        return False
    if m["s"] is not None:
        return _near(mine, m["s"], 0.05) and _near(theirs, m["s2"], 0.05) and mine > theirs
    return mine == theirs and _why(ctx, m, best)


def check_cornered_loser_widest(ctx: Ctx, m: re.Match) -> bool:
    if not (check_meets(ctx, m) and ctx.record.get("cornered") and _widest(ctx)):
        return False
    runner, chosen = ctx.runner, ctx.chosen
    if m["n1"] is not None:
        return (_near(_sep(ctx, runner), m["n1"], 0.05) and _near(_sep(ctx, chosen), m["n2"], 0.05)
                and _width(ctx, runner) < _width(ctx, chosen))  # fmt: skip
    same_time = abs(_meeting(ctx, runner)[1] - _meeting(ctx, chosen)[1]) < 1e-9
    nearer = _sep(ctx, runner) < _sep(ctx, chosen)
    return _width(ctx, runner) == _width(ctx, chosen) and same_time and nearer


def check_meets(ctx: Ctx, m: re.Match, c: dict | None = None) -> bool:
    c = c or _subject(ctx, m)
    if c is None or c["outcome"] != "collision" or c["meets"] is None:
        return False
    if ctx.lines is None:  # against the record alone
        rec = c["meets"]
        truth = (rec["intruder"], rec["time_s"], rec["miss_m"], rec["needed_m"])
    else:
        truth = ctx.lines[c["action"]["index"]].meets
        if truth is None:
            return False
    who, when, miss, need = truth
    return (
        _name_ok(who, m["k"])
        and _near(when, m["t"], 0.05)
        and _near(miss, m["miss"], 0.5)
        and _near(need, m["need"], 0.5)
    )


def check_why_not_collision(ctx: Ctx, m: re.Match) -> bool:
    """A predicted collision: the predicted miss is inside d_min itself (issue 30: passes
    inside the margin only were called collisions)."""
    miss_inside = _meeting(ctx, ctx.runner)[2] < ctx.record["d_min_m"] if ctx.runner else False
    return check_meets(ctx, m) and not ctx.conflicts(ctx.chosen) and miss_inside


def check_both_conflict(ctx: Ctx, m: re.Match) -> bool:
    return check_meets(ctx, m) and ctx.conflicts(ctx.chosen) and not ctx.record.get("cornered")


def _meeting(ctx: Ctx, c: dict) -> tuple:
    if ctx.lines is not None:
        return ctx.lines[c["action"]["index"]].meets
    rec = c["meets"]
    return (rec["intruder"], rec["time_s"], rec["miss_m"], rec["needed_m"])


def check_cornered_loser(ctx: Ctx, m: re.Match) -> bool:
    if not (check_meets(ctx, m) and ctx.record.get("cornered")):
        return False
    mine, theirs = _meeting(ctx, ctx.chosen), _meeting(ctx, ctx.runner)
    if _widest(ctx):  # the pass widths tie before the meeting or the rest can decide
        if _width(ctx, ctx.runner) != _width(ctx, ctx.chosen) or m["how"] == "as soon and closer":
            return False
        if m["how"] == "sooner":
            return theirs[1] < mine[1] - 1e-9
        return (abs(theirs[1] - mine[1]) < 1e-9 and _sep(ctx, ctx.runner) == _sep(ctx, ctx.chosen)
                and _why(ctx, m, ctx.runner))  # fmt: skip
    if m["how"] == "sooner":
        return theirs[1] < mine[1] - 1e-9
    if m["how"] == "as soon and closer":
        return abs(theirs[1] - mine[1]) < 1e-9 and theirs[2] < mine[2]
    return abs(theirs[1] - mine[1]) < 1e-9 and theirs[2] == mine[2] and _why(ctx, m, ctx.runner)


def check_every(ctx: Ctx, m: re.Match) -> bool:
    return all(ctx.conflicts(k) for k in ctx.kids.values())


def check_cornered(ctx: Ctx, m: re.Match) -> bool:
    kids = list(ctx.kids.values())
    if not (ctx.record.get("cornered") and all(ctx.conflicts(k) for k in kids)):
        return False
    if max(kids, key=lambda k: _rank(ctx, k)) is not ctx.chosen:  # the rule really chose it
        return False
    if not _stay_head_ok(ctx, m):
        return False
    c = ctx.chosen["action"]["index"]
    others = [k for k in kids if ctx.flies[k["action"]["index"]] != ctx.flies[c]]
    mine = _meeting(ctx, ctx.chosen)
    best = max(others, key=lambda k: _rank(ctx, k)) if others else None
    if best is None:
        return m["t"] is None and m["t3"] is None
    theirs = _meeting(ctx, best)
    if m["t"] is not None:
        return (
            _near(mine[1], m["t"], 0.05)
            and _near(theirs[1], m["t2"], 0.05)
            and (mine[1] > theirs[1])
        )
    if m["t3"] is not None:
        return (
            abs(mine[1] - theirs[1]) < 1e-9
            and _near(mine[1], m["t3"], 0.05)
            and _near(mine[2], m["m"], 0.05)
            and _near(theirs[2], m["m2"], 0.05)
            and mine[2] > theirs[2]
        )
    return abs(mine[1] - theirs[1]) < 1e-9 and mine[2] == theirs[2] and _why(ctx, m, best)


def check_keeps(ctx: Ctx, m: re.Match) -> bool:
    c = _subject(ctx, m)
    if c is None or ctx.conflicts(c) or c["outcome"] == "collision":
        return False
    if ctx.lines is None:
        sep, who = c["predicted_min_separation_m"], c["closest_intruder"]
        reaches = c["outcome"] == "goal"
    else:
        line = ctx.lines[c["action"]["index"]]
        sep, who, reaches = line.min_sep, line.closest, line.end == GOAL
        if not math.isclose(c["predicted_min_separation_m"] or math.inf, sep, abs_tol=0.01):
            return False  # the record must hold the number the words quote
    if (m["goal"] is not None) != reaches:
        return False
    if m["end"] is not None and not _end_ok(ctx, c, m["end"], m["too2"]):
        return False
    return sep is not None and _near(sep, m["n"], 0.5) and _name_ok(who, m["k"])


def check_unsure(ctx: Ctx, m: re.Match) -> bool:
    """The intruders named as less sure are those whose margin could bring them closer than
    the one named, the least first, as the record holds them and the line re-flown finds."""
    c = _subject(ctx, m)
    if c is None:
        return False
    said = [(w, float(n)) for w, n in re.findall(r"intruder ([^\s;,()]+) \(could pass at "
                                                 r"(\d+) m\)", m["list"])]  # fmt: skip
    shown = len(said) + (int(m["more"]) if m["more"] else 0)
    held = [tuple(u) for u in c.get("unsure") or []]
    if ctx.lines is not None:
        truth = ctx.lines[c["action"]["index"]].unsure
        if len(truth) != len(held) or any(
            not _name_ok(a, str(b)) or not math.isclose(x, y, abs_tol=0.01)
            for (a, x), (b, y) in zip(truth, held, strict=True)
        ):
            return False
    return shown == len(held) and all(
        _name_ok(who, w) and _near(could, n, 0.5)
        for (w, n), (who, could) in zip(said, held, strict=False)
    )


def check_clear(ctx: Ctx, m: re.Match) -> bool:
    c = _subject(ctx, m)
    reaches = c is not None and c["outcome"] == "goal"
    return (
        c is not None
        and not ctx.record["state"]["intruders"]
        and ((m["goal"] is not None) == reaches)
    )


def check_ends(ctx: Ctx, m: re.Match) -> bool:
    return _end_ok(ctx, _subject(ctx, m), m["how"], m["too"])


_END_CODES = {"ends out of bounds": ("out_of_bounds", OUT_OF_BOUNDS),
              "ends at the time-out": ("timeout", 4), "ends timeout": ("timeout", 4)}  # fmt: skip


def _end_ok(ctx: Ctx, c: dict | None, how: str, too: str | None) -> bool:
    """An option's line end: the record's and the tree's; a time-out only where the
    episode's own limit falls within the search's horizon; said of another option as a
    reason against it only when the chosen line does not end so too (else misleading)."""
    if c is None:
        return False
    outcome, code = _END_CODES[how]
    if c["outcome"] != outcome:
        return False
    if ctx.lines is not None and ctx.lines[c["action"]["index"]].end != code:
        return False
    if c is ctx.chosen:
        ctx.said_chosen_end = True
    if outcome == "timeout" and ctx.run is not None:
        left = (ctx.run.steps_limit - ctx.index) * ctx.cfg.decision_period_s
        if left > ctx.cfg.depth * ctx.cfg.action_hold_s + 1e-9:
            return False  # the episode had the time: no time-out can end this line
    same = c is not ctx.chosen and ctx.chosen["outcome"] == c["outcome"]
    if same != (too is not None):
        if same:  # a reason that is none: the chosen line ends so as well
            ctx.audit.mislead("line end given as a reason", f"{ctx.label}: {how}")
            return True
        return False
    return True


def check_every_end(ctx: Ctx, m: re.Match) -> bool:
    outcome = _END_CODES[m["how"]][0]
    return all(k["outcome"] == outcome for k in ctx.kids.values())


def check_margin(ctx: Ctx, m: re.Match) -> bool:
    """Inside the margin, not inside d_min: the miss is at least d_min."""
    if not check_meets(ctx, m) or ctx.conflicts(ctx.chosen):
        return False
    d_min = ctx.record["d_min_m"]
    miss, need = float(m["miss"]), float(m["need"])
    return miss >= d_min - 0.5 and _near(need - d_min, m["mg"], 1.0) and _near(d_min, m["dm"], 0.5)


def _risk_ok(c: dict, said: str | None) -> bool:
    share = c["collision_share"]
    if said is None:
        return share is None or share < 0.005
    return share is not None and f"{100 * share:.0f}" == said


def check_lower(ctx: Ctx, m: re.Match) -> bool:
    c, chosen = _subject(ctx, m), ctx.chosen
    return (
        c is not None
        and m["a"] == f"{c['q']:.3f}"
        and m["b"] == f"{chosen['q']:.3f}"
        and m["a"] != m["b"]
        and c["q"] < chosen["q"]
        and _risk_ok(c, m["risk"])
    )


def check_higher(ctx: Ctx, m: re.Match) -> bool:
    c = _subject(ctx, m) if m["opt"] else ctx.runner
    a, b = m["a"] or m["a2"], m["b"] or m["b2"]
    va, vb = m["va"] or m["va2"], m["vb"] or m["vb2"]
    risk = m["risk"] if m["opt"] else m["risk2"]
    chosen = ctx.chosen
    return (
        c is not None
        and a == f"{c['q']:.3f}"
        and b == f"{chosen['q']:.3f}"
        and a != b
        and c["q"] > chosen["q"]
        and int(va) == c["visits"] < chosen["visits"] == int(vb)
        and _risk_ok(c, risk)
    )


def _why(ctx: Ctx, m: re.Match, other: dict) -> bool:
    """The stated decider is the first key the planner's ranking separates the two by."""
    chosen = ctx.chosen
    cv, ov = chosen["visits"], other["visits"]
    cq, oq = chosen["q"], other["q"]
    first_in_order = chosen["action"]["index"] < other["action"]["index"]
    why = m["why"]
    if ctx.sampled:
        if cv != ov:
            return m["wa"] is not None and int(m["wa"]) == cv > ov == int(m["wb"])
        if cq != oq:
            return m["wn"] is not None and int(m["wn"]) == cv and cq > oq
        return m["wm"] is not None and int(m["wm"]) == cv and first_in_order
    if cq != oq:
        return why == "a higher Q beyond 3 decimals decided" and cq > oq
    return why == "the tie goes to the first in action order" and first_in_order


def check_tie(ctx: Ctx, m: re.Match) -> bool:
    other = _subject(ctx, m) if m["opt"] else ctx.runner
    chosen = ctx.chosen
    said = m["a"] or m["a2"]
    return (
        other is not None
        and f"{other['q']:.3f}" == f"{chosen['q']:.3f}" == said
        and _why(ctx, m, other)
    )


def check_q(ctx: Ctx, m: re.Match) -> bool:
    c, chosen = ctx.runner, ctx.chosen
    if c is None or m["a"] != f"{c['q']:.3f}" or m["b"] != f"{chosen['q']:.3f}":
        return False
    if not (c["q"] < chosen["q"] and m["a"] != m["b"]):  # "Q a against b" says it is lower
        return False
    if ctx.sampled != (m["va"] is not None):
        return False
    return m["va"] is None or (
        int(m["va"]) == c["visits"] and int(m["vb"]) == chosen["visits"] and _risk_ok(c, m["risk"])
    )


def check_support(ctx: Ctx, m: re.Match) -> bool:
    if m["all"] is not None:  # an exhaustive search that chose by the cornered rule
        return not ctx.sampled and bool(ctx.record.get("cornered"))
    if m["p"] is None:
        return not ctx.sampled and ctx.chosen["q"] == max(k["q"] for k in ctx.kids.values())
    if not ctx.sampled:
        return False
    if ctx.decision is not None and ctx.decision.tree is not None:
        tree = ctx.decision.tree
        node = next(c for c in tree.children_of(0) if tree.action[c] == ctx.decision.action)
        share = tree.visits[node] / tree.visits[0]
    else:
        share = ctx.record["confidence"]
    return f"{100 * share:.0f}" == m["p"]


def _station_at(run: Run, t: float) -> tuple[float, float, float]:
    """The service point in effect at ``t`` (summary: re-planned points with their times)."""
    points = [p for p in run.summary["mission"]["service_points"] if p[0] <= t + 1e-9]
    return tuple(points[-1][1:])


def _phase_at(run: Run, t: float) -> str:
    phases = [ph for when, ph in run.summary["mission"]["transitions"] if when <= t + 1e-9]
    return phases[-1] if phases else ""


def check_orbit_where(ctx: Ctx, m: re.Match) -> bool:
    """Orbiting only on the circle (within a tenth of its radius), about the service point
    in effect, at its height; joining says how far from the centre it is."""
    run, own, t = ctx.run, ctx.record["state"]["ownship"], ctx.record["t"]
    x, y, h = _station_at(run, t)
    r = run.mission.radius_m
    d = math.hypot(own["x"] - x, own["y"] - y)
    if _phase_at(run, t) != "on_station":
        return False
    cx, cy = m["x"] or m["x2"], m["y"] or m["y2"]
    if not (_near(x, cx, 0.5) and _near(y, cy, 0.5)):
        return False
    if m["r"] is not None:
        return _near(r, m["r"], 0.5) and _near(h, m["h"], 0.5) and abs(d - r) <= ON_ORBIT_SHARE * r
    if m["d"] is not None:
        return _near(r, m["r2"], 0.5) and _near(d, m["d"], 0.5) and abs(d - r) > ON_ORBIT_SHARE * r
    side = "outside" if d > r else "inside"
    return _near(r, m["r3"], 0.5) and _near(abs(d - r), m["off"], 0.5) and m["side"] == side


def check_orbit_pass(ctx: Ctx, m: re.Match) -> bool:
    """The orbit ahead against the intruders the record says the planner saw, as the record
    holds it; its flight counted (the words are a prediction on each intruder's present
    turn)."""
    run, rec = ctx.run, ctx.record
    station = _station_at(run, rec["t"])
    c = replace(run.mission, station=station)
    own = Ownship(**{k: rec["state"]["ownship"][k] for k in ("x", "y", "h", "speed", "heading",
                                                             "bank")})  # fmt: skip
    intruders = [Intruder(**i) for i in rec["state"]["intruders"]]
    horizon = ctx.cfg.depth * ctx.cfg.action_hold_s
    sep, who, when = orbit_clearance(c, own, intruders, horizon)
    ok = (
        who is not None
        and _name_ok(who.removeprefix("intruder "), m["k"])
        and _near(sep, m["n"], 0.5)
        and _near(when, m["t"], 0.5)
        and _near(rec["branch_min_separation_m"], m["n"], 0.5)
        and (m["lim"] is None or _near(CONFLICT_FACTOR * rec["d_min_m"], m["lim"], 0.5))
    )
    if m["old"] is not None:  # said as what will happen, not as the conditional it is
        ctx.audit.mislead("orbit: a pass said as certain", ctx.label)
    times, samples = ctx.flight
    flown = flown_min(times, samples, rec["t"], rec["t"] + horizon, only=m["k"])
    if math.isfinite(flown):
        ctx.audit.flown("orbit: intruder passes", flown >= float(m["n"]) - FLIGHT_TOLERANCE_M,
                        f"{ctx.label}: said {m['n']} m, flown {flown:.0f} m")  # fmt: skip
    return ok


CHECKS = {
    "orbit: where": check_orbit_where,
    "orbit: intruder passes": check_orbit_pass,
    "verb": check_verb,
    "why not names the runner-up": check_runner,
    "cornered: chose by the stated rule": check_cornered,
    "cornered: chose by the widest rule": check_cornered_widest,
    "cornered: why not, widest": check_cornered_loser_widest,
    "why not: a collision": check_why_not_collision,
    "why not: both conflict": check_both_conflict,
    "cornered: why not": check_cornered_loser,
    "meets k at N m": check_meets,
    "every option conflicts": check_every,
    "keeps N m from k": check_keeps,
    "keeps: less sure of": check_unsure,
    "keeps clear": check_clear,
    "line ends": check_ends,
    "every option ends": check_every_end,
    "why not: inside the margin": check_margin,
    "Q lower": check_lower,
    "Q higher, fewer simulations": check_higher,
    "Q tie says what decided": check_tie,
    "Q comparison": check_q,
    "support": check_support,
}


def audit_text(audit: Audit, ctx: Ctx, text: str, where: str, label: str) -> None:
    """Every claim in ``text`` (the sentence "s" or the counterfactual "c"), checked."""
    rest = text
    ctx.text = where
    for name, places, pattern in _COMPILED:
        if where not in places:
            continue
        for m in pattern.finditer(rest):
            audit.claim(name, CHECKS[name](ctx, m), f"{label}: {m.group(0)!r} in {text!r}")
            rest = rest[: m.start()] + "\0" * (m.end() - m.start()) + rest[m.end() :]
    audit.claim("every claim parsed", re.fullmatch(r"[\s;:,()\0]*", rest) is not None,
                f"{label}: unparsed {rest.replace(chr(0), '')!r}")  # fmt: skip
    if where == "o":  # an orbit decision names no options
        return
    # a named option is never the chosen manoeuvre offered as an alternative
    chosen = ctx.chosen["action"]["index"]
    named = rf"(?:^|: |; )({OPT}) (?:meets|is as good|has the higher|scores lower|ends)"
    for opt in re.findall(named, text):
        if where == "s" and PHRASE[opt] != chosen:
            other = ctx.flies[PHRASE[opt]] != ctx.flies[chosen]
            audit.claim("alternative is another manoeuvre", other, f"{label}: {text!r}")


# ---------------------------------------------------------------------- whole decisions
def audit_run(audit: Audit, run: Run) -> None:
    times, samples = flight(run.folder)
    errors = []
    run.contexts = [
        _context(run, r, run.decisions[i] if run.decisions else None, i)
        for i, r in enumerate(run.records)
    ]
    for i, (record, ctx) in enumerate(zip(run.records, run.contexts, strict=True)):
        label = f"{run.folder.name}#{i}"
        ctx.audit, ctx.label, ctx.run, ctx.index = audit, label, run, i
        ctx.flight = (times, samples)
        _audit_next_period(audit, ctx, times, samples, label)
        if record["planner"] == "orbit":
            audit_text(audit, ctx, record["explanation"], "o", label)
            continue
        decision = ctx.decision
        audit_text(audit, ctx, record["explanation"], "s", label)
        if record["counterfactual"]:
            audit_text(audit, ctx, record["counterfactual"], "c", label)
        if ctx.chosen["outcome"] in ("out_of_bounds", "timeout") and not ctx.said_chosen_end:
            audit.mislead("chosen line's end unsaid", f"{label}: {record['explanation']!r}")
        _audit_record(audit, ctx, label)
        if decision is not None and decision.tree is not None:
            _audit_drawing(audit, ctx, decision, label)
        _audit_keeps_flown(audit, ctx, times, samples, label)
        error = _audit_trust_window(audit, ctx, times, samples, label)
        if error is not None:
            errors.append(error)
    _audit_summary(audit, run, errors)
    _audit_overview(audit, run)


def _context(run: Run, record: dict, decision, i: int) -> Ctx:
    if record["planner"] == "orbit":  # no options: the orbit's own claims
        return Ctx(record, run.config, {}, {}, {}, None, decision)
    kids = {c["action"]["index"]: c for c in record["children"]}
    chosen = kids[record["action"]["index"]]
    flies = {a: flies_of(record, c, run.config) for a, c in kids.items()}
    lines = None
    if decision is not None and decision.tree is not None:
        lines = line_truths(decision, record, run.config, run.goals[i] if run.goals else run.goal)
    ctx = Ctx(record, run.config, kids, chosen, flies, lines, decision)
    head = re.match(rf"^why not ({OPT})", record["counterfactual"] or "")
    ctx.runner = kids.get(PHRASE[head.group(1)]) if head else None
    return ctx


def _audit_next_period(audit: Audit, ctx: Ctx, times, samples, label: str) -> None:
    """`uavxai explain` labels ``predicted_min_separation_m`` "predicted minimum separation
    over the next decision period": set against that period as flown."""
    sep = ctx.record.get("predicted_min_separation_m")
    if sep is None:
        return
    t = ctx.record["t"]
    flown = flown_min(times, samples, t, t + ctx.cfg.decision_period_s)
    if math.isfinite(flown):
        audit.flown("explain: next period's separation", abs(flown - sep) <= FLIGHT_TOLERANCE_M,
                    f"{label}: {sep:.0f} m, flown {flown:.0f} m")  # fmt: skip


def _audit_keeps_flown(audit: Audit, ctx: Ctx, times, samples, label: str) -> None:
    """The chosen option's "is predicted to keep N m from intruder k", against the flight
    over the chosen line's horizon (the flight followed that line, not the others')."""
    said = re.search(rf"; (?:{OPT}) {KEEPS}", ctx.record["explanation"])
    horizon = ctx.record.get("branch_horizon_s") or 0.0
    if said is None or not horizon > 0:
        return
    t = ctx.record["t"]
    flown = flown_min(times, samples, t, t + horizon, only=said["k"])
    if math.isfinite(flown):
        audit.flown("keeps N m from k", flown >= float(said["n"]) - FLIGHT_TOLERANCE_M,
                    f"{label}: said {said['n']} m from {said['k']}, flown {flown:.0f}")  # fmt: skip


def _audit_record(audit: Audit, ctx: Ctx, label: str) -> None:
    """What the record says beside the words: which manoeuvre each option flies, and the
    number the trust figure is computed from is the one the sentence quotes."""
    for a, c in ctx.kids.items():
        audit.claim("record: the manoeuvre flown", c["flies"] == ACTIONS[ctx.flies[a]].name,
                    f"{label}: {c['action']['name']} flies {c['flies']}")  # fmt: skip
        own = ctx.record["state"]["ownship"]
        act = ACTIONS[a]
        step = c["action"]["bank_cmd_rad"] - own["bank"]
        lim = math.radians(ctx.cfg.bank_limit_deg)
        at_limit = abs(step) < BANK_EPS and abs(own["bank"]) >= lim - BANK_EPS
        sign_ok = (np.sign(step) if abs(step) > BANK_EPS else 0) == act.bank or at_limit
        audit.claim("option phrase matches its command",
                    bool(sign_ok) and np.sign(c["action"]["accel_mps2"]) == act.accel,
                    f"{label}: {act.phrase}")  # fmt: skip
    branch = ctx.record["branch_min_separation_m"]
    quoted = ctx.chosen["predicted_min_separation_m"]
    audit.claim("trust figure is the quoted number", branch == quoted, f"{label}: {branch}")
    if ctx.lines is not None:
        line = ctx.lines[ctx.chosen["action"]["index"]]
        said = ctx.record["branch_horizon_s"]
        audit.claim("trust horizon is the branch's", abs(said - line.horizon) < 1e-6,
                    f"{label}: {said} against {line.horizon}")  # fmt: skip


def _audit_drawing(audit: Audit, ctx: Ctx, decision, label: str) -> None:
    """The tree graph and the plan label the viewer shows for the decision."""
    tree, graph = decision.tree, tree_graph(decision)
    green = {int(n[1:]) for n, color in zip(graph.node_ids, graph.colors, strict=True)
             if color == CHOSEN_COLOR and n != "n0"}  # fmt: skip
    root = next(int(c) for c in tree.children_of(0) if tree.action[c] == decision.action)
    audit.claim("tree: chosen action drawn green", root in green, label)
    plan = tree.best_line(root)
    for depth in range(1, int(tree.depth.max(initial=0)) + 1):
        at = {n for n in green if tree.depth[n] == depth}
        if not at:
            continue
        ok = len(at) == 1 and len(plan) >= depth and plan[depth - 1] in at
        audit.claim("tree: green node on the executed plan", ok, f"{label} depth {depth}")
    line = ctx.lines[decision.action]
    text = _plan_label(decision, [])
    m = re.fullmatch(r"plan: (\d+) m from (\S+)", text)
    ok = m is not None and _near(line.min_sep, m[1], 0.5) and _name_ok(line.closest, m[2])
    if not math.isfinite(line.min_sep):
        ok = text == "plan"
    audit.claim("plan label: branch minimum and its intruder", ok, f"{label}: {text}")


def _audit_trust_window(audit, ctx: Ctx, times, samples, label) -> float | None:
    """The window the trust figure compares; how often flight held the quoted separation is
    recorded for the report (the words call it a prediction, so it is no false claim)."""
    branch, horizon = ctx.record["branch_min_separation_m"], ctx.record["branch_horizon_s"]
    if branch is None or not horizon > 0:
        return None
    flown = flown_min(times, samples, ctx.record["t"], ctx.record["t"] + horizon)
    if not math.isfinite(flown):
        return None
    audit.info["predictions compared with flight"] += 1
    audit.info["held within 10 m"] += flown >= branch - 10.0
    return abs(branch - flown)


def _audit_summary(audit: Audit, run: Run, errors: list[float]) -> None:
    trust = run.summary["trust"]["separation_error_m"]
    if not errors:
        audit.claim("summary trust", trust["mean"] is None, run.folder.name)
        return
    mine = {"mean": np.mean(errors), "p95": np.percentile(errors, 95), "max": np.max(errors)}
    for key, value in mine.items():
        audit.claim("summary trust", abs(trust[key] - value) < 0.01,
                    f"{run.folder.name} {key}: {trust[key]} against {value}")  # fmt: skip
    audit.info["trust mean (m), sum over runs"] += int(round(mine["mean"]))


def _audit_overview(audit: Audit, run: Run) -> None:
    """`uavxai explain RUN`: "N steered away from a predicted conflict" and its list."""
    text = explain_command(run.folder, None)
    said = int(re.search(r"; (\d+) steered away from a predicted conflict", text).group(1))
    truth = []
    for i, ctx in enumerate(run.contexts):
        hold = ctx.kids.get(HOLD)
        if hold is None or not ctx.chosen:
            continue
        index = ctx.chosen["action"]["index"]
        other = ctx.flies[index] != ctx.flies[HOLD]
        if other and ctx.conflicts(hold) and not ctx.conflicts(ctx.chosen):
            truth.append(i)
    audit.claim("steered away from a predicted conflict", said == len(truth),
                f"{run.folder.name}: said {said}, true {len(truth)}")  # fmt: skip
    for i in (int(x) for x in re.findall(r"^  \[(\d+)\]", text, flags=re.M)):
        audit.claim("steered away from a predicted conflict", i in truth, f"{run.folder.name}#{i}")


# ------------------------------------------------------------------------------- tests
def fast_runs(tmp: Path) -> list[Run]:
    """Short runs with real avoidance, kinematic for speed (about 20 s in all)."""
    sims = {"mcts": {"simulations": 100}}
    return [
        # dense manoeuvring traffic: cornered decisions, then a collision at step 55 (with 3 s
        # of turn cover; the default 4 s flies clear of this one)
        fly_recorded(
            scenario("manoeuvring", seed=6, intruders={"count": 40},
                     avoidance={"mcts": {"simulations": 100, "reach_horizon_s": 3.0}}),
            "mcts",
            tmp / "dense-collision",
        ),  # fmt: skip
        # the same traffic, cornered decisions chosen by the widest pass (issue 31, a32)
        fly_recorded(
            scenario("manoeuvring", seed=6, intruders={"count": 40},
                     avoidance={"max_steps": 60, "mcts": {"simulations": 100,
                                "reach_horizon_s": 3.0, "cornered_rule": "widest"}}),
            "mcts",
            tmp / "dense-widest",
        ),  # fmt: skip
        fly_recorded(
            scenario("crossing_swarm", avoidance={"max_steps": 60, **sims}),
            "mcts",
            tmp / "crossing",
        ),  # fmt: skip
        fly_recorded(scenario("head_on", avoidance=sims), "mcts", tmp / "head-on"),
        # the vertical action set: climbs and descends, clamped when already under way
        fly_recorded(
            scenario("manoeuvring", seed=1, intruders={"count": 40},
                     avoidance={"actions": "vertical", "max_steps": 40, **sims}),
            "mcts",
            tmp / "vertical",
        ),  # fmt: skip
        fly_recorded(
            scenario("head_on", avoidance={"max_steps": 30, "mcts": {"depth": 3}}),
            "exhaustive",
            tmp / "head-on-exhaustive",
        ),  # fmt: skip
    ]


# The claim types the fast runs must exercise: an audit that never meets a claim proves nothing.
MUST_SEE = (
    "verb", "why not names the runner-up", "cornered: chose by the stated rule",
    "cornered: why not", "cornered: chose by the widest rule", "cornered: why not, widest",
    "meets k at N m", "keeps N m from k", "Q lower", "Q tie says what decided",
    "Q comparison", "support", "tree: green node on the executed plan",
    "plan label: branch minimum and its intruder", "summary trust",
    "steered away from a predicted conflict", "alternative is another manoeuvre",
    "keeps: less sure of",
)  # fmt: skip


@pytest.fixture(scope="module")
def fast_audit(tmp_path_factory) -> tuple[Audit, list[Run]]:
    runs = fast_runs(tmp_path_factory.mktemp("audit"))
    audit = Audit()
    for run in runs:
        audit_run(audit, run)
    return audit, runs


def test_every_claim_of_recorded_runs_is_true(fast_audit):
    audit, runs = fast_audit
    print("\n" + audit.table())
    assert any(r.summary["outcome"] == "collision" for r in runs)  # the situation under test
    assert any(d.cornered for r in runs for d in r.decisions)
    missing = [k for k in MUST_SEE if not audit.checked[k]]
    assert not missing, f"claim types never met: {missing}"
    _assert_audit(audit)


def test_the_audit_catches_false_claims(fast_audit):
    """Each check can fail: corrupt true sentences the way the issue found them false."""
    _, runs = fast_audit
    corrupted = [
        (r"predicted miss (\d+) m", lambda m: f"predicted miss {int(m.group(1)) + 7} m"),
        (r"is predicted to keep (\d+) m", lambda m: f"is predicted to keep {int(m[1]) + 3} m"),
        (r"scores lower \(Q (\d\.\d{3}) against (\d\.\d{3})",
         lambda m: f"scores lower (Q {m.group(2)} against {m.group(1)}"),
        (r"\((\d+) simulations against", lambda m: f"({m[1]}1 simulations against"),
        (r"this one had more simulations", lambda m: "the tie goes to the first in action order"),
        (r"^held its bank", lambda m: "banked right"),
        (r"its intruder latest \(in (\d+\.\d) s", lambda m: "its intruder latest (in 99.5 s"),
        (r"(\d+)% of simulations agree", lambda m: f"{int(m.group(1)) + 1}% of simulations agree"),
    ]  # fmt: skip
    for pattern, change in corrupted:
        audit = Audit()
        hits = 0
        for run in runs:
            for i, record in enumerate(run.records):
                for key, where in (("explanation", "s"), ("counterfactual", "c")):
                    text = record[key] or ""
                    bad = re.sub(pattern, change, text, count=1)
                    if bad == text:
                        continue
                    hits += 1
                    ctx = run.contexts[i]
                    audit_text(audit, ctx, bad, where, f"#{i}")
        assert hits, pattern  # the corruption found something to corrupt
        assert sum(audit.false.values()) >= hits, (pattern, audit.table())


def mission_run(tmp: Path, seed: int = 3, service_s: float = 60.0, count: int = 20) -> Run:
    """A whole mission in JSBSim among manoeuvring traffic seen through ADS-B: transit, the
    orbit on station (left to avoid traffic, rejoined), home."""
    sc = scenario("manoeuvring", seed=seed, intruders={"count": count},
                  avoidance={"mcts": {"simulations": 100}})  # fmt: skip
    mission = replace(MissionConfig.from_scenario(sc, (600.0, 600.0, 120.0)), service_s=service_s)
    run = fly_recorded(sc, "mcts", tmp / f"mission-{seed}", dynamics="jsbsim", mission=mission)
    # checked against the record, as a `uavxai run` is: the lines are re-flown in the
    # kinematic runs (the planner's model of the JSBSim ownship is not all in the record)
    run.decisions = []
    return run


def audit_of(runs: list[Run]) -> Audit:
    audit = Audit()
    for run in runs:
        audit_run(audit, run)
    return audit


# What the flight may contradict (issue 30): a share of the predictions set against it.
CONTRADICTED_SHARE = 0.10
MISLEADING_SHARE = 0.005


def _assert_audit(audit: Audit) -> None:
    t = audit.totals()
    assert t["false"] == 0, "\n".join(audit.failures)
    assert t["misleading"] <= MISLEADING_SHARE * t["claims"], "\n".join(audit.failures)
    assert t["flown"] and t["contradicted"] <= CONTRADICTED_SHARE * t["flown"], audit.table()


@pytest.mark.slow
def test_every_claim_of_a_jsbsim_mission_is_true(tmp_path):
    """Issue 30: the audit sees the orbit's sentences and every phase of a mission flown in
    JSBSim, and counts what the flight contradicts."""
    run = mission_run(tmp_path)
    audit = audit_of([run])
    print(f"\n{len(run.records)} decisions, {run.summary['outcome']}")
    print(audit.table())
    phases = {ph for _, ph in run.summary["mission"]["transitions"]}
    assert {"transit", "on_station", "avoiding", "returning"} <= phases
    assert audit.checked["orbit: where"] and audit.checked["orbit: intruder passes"]
    _assert_audit(audit)


@pytest.mark.slow
def test_audit_at_scale(tmp_path):
    """More seeds, denser traffic, both tree planners; prints the table (issue 14's audit had
    881 decisions and 68,924 claims)."""
    audit, n = Audit(), 0
    runs = []
    for seed in range(6):
        for count in (40, 60):
            sc = scenario("manoeuvring", seed=seed, intruders={"count": count},
                          avoidance={"max_steps": 120})  # fmt: skip
            runs.append(fly_recorded(sc, "mcts", tmp_path / f"m{count}-{seed}"))
    for seed in range(3):  # the vertical action set
        sc = scenario("manoeuvring", seed=seed, intruders={"count": 40},
                      avoidance={"actions": "vertical", "max_steps": 120})  # fmt: skip
        runs.append(fly_recorded(sc, "mcts", tmp_path / f"vertical-{seed}"))
    for name in ("crossing_swarm", "head_on"):
        for seed in range(3):
            sc = scenario(name, seed=seed, avoidance={"max_steps": 120})
            runs.append(fly_recorded(sc, "mcts", tmp_path / f"{name}-{seed}"))
    runs.append(fly_recorded(scenario("head_on", avoidance={"max_steps": 80, "mcts": {"depth": 3}}),
                             "exhaustive", tmp_path / "exhaustive"))  # fmt: skip
    for run in runs:
        audit_run(audit, run)
        n += len(run.records)
    outcomes = Counter(r.summary["outcome"] for r in runs)
    print(f"\n{len(runs)} runs, {n} decisions, outcomes {dict(outcomes)}")
    print(audit.table())
    print({k: v for k, v in audit.info.items()})
    _assert_audit(audit)


def test_a_jsbsim_run_through_the_command_line(tmp_path):
    """`uavxai run` (JSBSim, MAVLink): its files alone, every claim against its record and
    the trust figure against its trajectory."""
    from uavxai.cli import main

    sc = scenario("head_on", avoidance={"max_steps": 25, "mcts": {"simulations": 60}},
                  log={"rerun": False})  # fmt: skip
    path = tmp_path / "head_on.yaml"
    path.write_text(json.dumps(sc.model_dump(mode="json")))
    assert main(["run", str(path), "--out", str(tmp_path / "run")]) == 0
    folder = tmp_path / "run"
    records = [json.loads(line) for line in (folder / "decisions.jsonl").open()]
    summary = json.loads((folder / "summary.json").read_text())
    run = Run(folder, PlannerConfig.from_scenario(sc), episode_goal(sc), records, [], summary)
    audit = Audit()
    audit_run(audit, run)
    print("\n" + audit.table())
    assert audit.checked["summary trust"] == 3 and audit.checked["verb"] == len(records)
    assert sum(audit.false.values()) == 0, "\n".join(audit.failures)
