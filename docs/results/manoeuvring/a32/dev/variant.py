"""Fly rows with mcts_sep under a cornered-rule variant: python variant.py V SCENARIO N DYN SEED..."""
import sys, math
import uavxai.avoidance.lines as L
from uavxai.campaign.episode import campaign_spec, planner_for
from uavxai.scenario import load_scenario
from uavxai.sim.build import fly
V = sys.argv[1]; scn = load_scenario(sys.argv[2]); n = int(sys.argv[3]); dyn = sys.argv[4]
DMIN = 50.0
def key_v1(c, by_value=False):
    m = c.meets
    return (not L.leaves(c), -math.inf if m is None else round(m.time_s, 6),
            c.predicted_min_separation_m, *L.search_key(c, by_value))
def key_v2(c, by_value=False):
    m = c.meets
    return (not L.leaves(c), c.predicted_min_separation_m >= DMIN, -math.inf if m is None else round(m.time_s, 6),
            c.predicted_min_separation_m, *L.search_key(c, by_value))
def key_v3(c, by_value=False):
    m = c.meets
    return (not L.leaves(c), c.predicted_min_separation_m, -math.inf if m is None else round(m.time_s, 6),
            *L.search_key(c, by_value))
def key_v4(c, by_value=False):
    m = c.meets
    return (not L.leaves(c), min(c.predicted_min_separation_m, 2 * DMIN), -math.inf if m is None else round(m.time_s, 6),
            c.predicted_min_separation_m, *L.search_key(c, by_value))
if V != "v0":
    L.cornered_key = {"v1": key_v1, "v2": key_v2, "v3": key_v3, "v4": key_v4}[V]
for s in sys.argv[5:]:
    planner = planner_for(scn, "mcts_sep"); planner.__dict__.pop("plan", None); plan = planner.plan; last = []
    def rec(own, intruders, goal, *, step, _plan=plan, _last=last, **kw):
        d = _plan(own, intruders, goal, step=step, **kw)
        _last.append((step, round(own.x), round(own.y), round(own.h), d.cornered))
        return d
    planner.plan = rec
    r = fly(campaign_spec(scn, n, int(s), dyn), planner)
    ncorn = sum(1 for x in last if x[4])
    print(V, s, r.outcome.value, r.steps, round(r.min_separation_m, 1), "last", last[-1][:4], "cornered", ncorn, flush=True)
