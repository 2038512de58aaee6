"""Persistent traffic in both worlds: an intruder that leaves is replaced at the edge."""

from __future__ import annotations

import numpy as np

from uavxai.scenario import default_scenario
from uavxai.sim.kinematic import KinematicWorld

OUTBOUND = {
    "list": [
        {"x": 1950, "y": 1000, "h": 120, "heading_deg": 90, "speed_mps": 25},  # leaves east
        {"x": 1000, "y": 1500, "h": 120, "heading_deg": 180, "speed_mps": 20},
    ]
}


def _inside(state, world) -> int:
    p = state.pos[1:]
    return int(np.sum((p[:, 0] >= 0) & (p[:, 0] <= 2000) & (p[:, 1] >= 0) & (p[:, 1] <= 2000)))


def test_kinematic_density_stays_constant_over_a_long_run() -> None:
    sc = default_scenario("flow", intruders={"count": 20}, seed=3)
    world = KinematicWorld(sc)
    world.command_ownship(bank_cmd_rad=0.3, accel_cmd_mps2=0.0)  # circle at the start
    world.advance(400.0)
    s = world.state()
    assert _inside(s, world) >= 19  # a leaver is replaced within the next pilot second
    numbers = [int(i.removeprefix("intruder-")) for i in s.ids[1:]]
    assert max(numbers) > 20 and len(set(numbers)) == 20  # newcomers get new numbers


def test_jsbsim_replaces_a_leaving_intruder_with_a_new_aircraft() -> None:
    from uavxai.dynamics.world import JSBSimWorld

    sc = default_scenario("flow-jsbsim", intruders=OUTBOUND, seed=1)
    with JSBSimWorld(sc) as world:
        assert world.state().ids == ("ownship", "intruder-1", "intruder-2")
        world.advance(6.0)
        s = world.state()
        # the leaver's row now holds a newcomer with a new number (never a reused one)
        assert int(s.ids[1].removeprefix("intruder-")) >= 3 and s.ids[2] == "intruder-2"
        p = s.pos[1]
        on_edge = min(p[0], 2000 - p[0], p[1], 2000 - p[1])
        assert on_edge < 200 and world.failure() is None  # entered at the edge, flying
        assert np.hypot(*(s.pos[1, :2] - s.pos[0, :2])) >= 300.0


def test_newcomers_never_reuse_a_number_when_a_campaign_draws_more_intruders() -> None:
    """A campaign draws `--intruders 40` from a scenario whose count is 20: newcomers must
    be numbered after the 40, or two aircraft would share an id (and a track)."""
    from uavxai.dynamics.traffic import draw_intruders

    sc = default_scenario("flow-ids", intruders={"count": 20}, seed=2)
    specs = draw_intruders(sc, np.random.default_rng(2), 40)
    world = KinematicWorld(sc, intruders=specs)
    world.advance(200.0)
    ids = world.state().ids[1:]
    assert len(set(ids)) == len(ids) == 40
    assert any(int(i.removeprefix("intruder-")) > 40 for i in ids)
