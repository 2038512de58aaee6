"""Traffic that persists: intruders that leave the area are replaced at its edge, so the
density stays constant (and uniform) over long runs."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.dynamics.flow import TrafficFlow, apply_entries
from uavxai.errors import UserError
from uavxai.scenario import default_scenario

BOX = ((0.0, 2000.0), (0.0, 2000.0))
N = 20


def initial(seed: int = 0):
    rng = np.random.default_rng(seed)
    pos = np.column_stack([rng.uniform(0, 2000, N), rng.uniform(0, 2000, N), np.full(N, 120.0)])
    heading = rng.uniform(0, 2 * math.pi, N)
    speed = rng.uniform(15, 30, N)
    vel = np.column_stack([speed * np.sin(heading), speed * np.cos(heading), np.zeros(N)])
    return [f"intruder-{k}" for k in range(1, N + 1)], pos, vel


def fly_straight(seconds: int, flow: TrafficFlow | None, dt: float = 1.0):
    """Straight-flying intruders; returns (count inside per step, central share per step,
    every id seen in order, per step the ids)."""
    ids, pos, vel = initial()
    inside, central, seen = [], [], list(ids)
    for _ in range(int(seconds / dt)):
        pos = pos + vel * dt
        if flow is not None:
            entries = flow.replace(pos)
            ids, pos, vel = apply_entries(ids, pos, vel, entries)
            seen += [e.id for e in entries]
        x, y = pos[:, 0], pos[:, 1]
        ok = (x >= 0) & (x <= 2000) & (y >= 0) & (y <= 2000)
        inside.append(int(ok.sum()))
        mid = (x >= 500) & (x <= 1500) & (y >= 500) & (y <= 1500)
        central.append(mid.sum() / max(ok.sum(), 1))
    return np.array(inside), np.array(central), seen


def test_without_flow_the_traffic_drains_away():
    inside, _, _ = fly_straight(400, None)
    assert inside[99] <= 5 and inside[-1] == 0


def test_density_stays_constant_and_uniform_with_replacement():
    flow = TrafficFlow(*BOX, first_number=N + 1, seed=3)
    inside, central, seen = fly_straight(3000, flow)
    assert np.all(inside == N)  # every leaver replaced in the same step
    assert flow.entered > 100  # the traffic really turned over, many times
    # uniform density: the central quarter of the area holds a quarter of the traffic
    # (time average over the long run; the initial traffic was uniform too)
    assert np.mean(central) == pytest.approx(0.25, abs=0.03)
    # ...and it does not drift: the first and second halves agree
    half = len(central) // 2
    assert abs(np.mean(central[:half]) - np.mean(central[half:])) < 0.04


def test_newcomers_get_new_increasing_ids_and_enter_heading_inward():
    flow = TrafficFlow(*BOX, first_number=N + 1, seed=1)
    _, _, seen = fly_straight(600, flow)
    numbers = [int(i.split("-")[1]) for i in seen]
    assert numbers[:N] == list(range(1, N + 1))
    assert numbers[N:] == list(range(N + 1, N + 1 + flow.entered))  # never reused
    for _ in range(500):
        e = flow.entry()
        on_edge = min(e.x, 2000 - e.x, e.y, 2000 - e.y)
        assert on_edge == pytest.approx(0.0, abs=1e-9)
        assert not flow.left(np.array([[e.x, e.y, e.h]]))[0]
        inward = np.array([1000.0 - e.x, 1000.0 - e.y])  # towards the centre
        normal = np.where(np.abs(inward) == 1000.0, np.sign(inward), 0.0)  # of its edge
        assert normal @ e.velocity[:2] > 0  # heading inward
        assert 100 <= e.h <= 140 and 15 <= e.speed_mps <= 30


def test_entry_directions_follow_the_cosine_law():
    flow = TrafficFlow(*BOX, seed=2)
    off = []
    for _ in range(4000):
        e = flow.entry()
        normal = {  # inward normal heading of the edge the newcomer is on
            e.y == 0.0: 0.0,
            e.x == 2000.0: 1.5 * math.pi,
            e.y == 2000.0: math.pi,
            e.x == 0.0: 0.5 * math.pi,
        }[True]
        off.append((e.heading_rad - normal + math.pi) % (2 * math.pi) - math.pi)
    off = np.abs(np.array(off))
    assert off.max() <= math.pi / 2
    # P(|theta| < 30 deg) = sin(30 deg) = 0.5 under pdf cos(theta) / 2
    share = np.mean(off < math.radians(30))
    assert abs(share - 0.5) < 4 * math.sqrt(0.25 / len(off))


def test_same_seed_same_traffic():
    a = [TrafficFlow(*BOX, seed=9).entry() for _ in range(1)]
    b = [TrafficFlow(*BOX, seed=9).entry() for _ in range(1)]
    c = [TrafficFlow(*BOX, seed=10).entry() for _ in range(1)]
    assert a == b and a != c


def test_from_scenario_and_bad_input():
    sc = default_scenario(seed=4, intruders={"count": 20}, world={"x": [0, 2000], "y": [0, 1000]},
                          ownship={"start": {"x": 100, "y": 100}, "goal": [1500, 800, 120]},
                          comms={"users": {"region": {"x": [200, 600], "y": [200, 600]}}})
    flow = TrafficFlow.from_scenario(sc)
    assert flow is not None and flow.next_number == 21 and flow.y_bounds == (0.0, 1000.0)
    assert TrafficFlow.from_scenario(sc.model_copy(update={
        "intruders": sc.intruders.model_copy(update={"flow": "none"})})) is None
    with pytest.raises(UserError, match="intruders.flow"):  # the schema names the key
        default_scenario(intruders={"flow": "bounce"})
    with pytest.raises(UserError):
        TrafficFlow((0, 0), (0, 1))


def test_newcomers_keep_clear_of_the_ownship():
    flow = TrafficFlow(*BOX, first_number=N + 1, seed=6)
    own = np.array([[1000.0, 0.0, 120.0]])  # the ownship on the south edge
    outside = np.array([[-10.0, 500.0, 120.0]] * 300)
    entries = flow.replace(outside, keep_clear=own, min_distance_m=400.0)
    assert len(entries) == 300
    assert all(math.hypot(e.x - 1000.0, e.y) >= 400.0 for e in entries)
    assert [e.number for e in entries] == list(range(N + 1, N + 301))  # no gaps from redraws
    with pytest.raises(UserError, match="ownship"):
        flow.replace(outside[:1], keep_clear=own, min_distance_m=5000.0)
