"""The encounter model: kinematics, and events anywhere along a segment."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.avoidance.model import (
    COLLISION,
    GOAL,
    NONE,
    OUT_OF_BOUNDS,
    EncounterModel,
    Track,
    intruder_margin,
    ownship_air,
    ownship_state,
    place_children,
    track_sigma,
)
from uavxai.avoidance.types import Ownship, PlannerConfig
from uavxai.units import G

RIGHT_HOLD = 7  # bank right, hold speed
HOLD = 4
FASTER = 3  # hold bank, speed up
SLOWER = 5  # hold bank, slow down


def fly_one(model, own: Ownship, action: int, goal, duration, pos=None, vel=None, **kw):
    pos = np.zeros((0, 3)) if pos is None else np.asarray(pos, dtype=float)
    vel = np.zeros((0, 3)) if vel is None else np.asarray(vel, dtype=float)
    track = model.predict(pos, vel, duration)
    return model.fly(
        ownship_state(own)[None], np.array([action]), np.asarray(goal, float), duration, track, **kw
    )


def test_pass_through_between_samples_is_a_collision():
    # One 4 s sub-step: at both ends the intruder is 72 m away, but it crosses the ownship's
    # track right where the ownship is at t = 2 s.
    cfg = PlannerConfig(substep_s=4.0)
    model = EncounterModel(cfg)
    own = Ownship(1000.0, 1000.0, 120.0, 20.0, 0.0)  # north at 20 m/s
    pos, vel = [[940.0, 1040.0, 120.0]], [[30.0, 0.0, 0.0]]  # east at 30 m/s
    seg = fly_one(model, own, HOLD, (1000, 1900, 120), 4.0, pos, vel)
    samples = seg.samples[0]
    assert samples.shape == (2, 3)  # one sub-step: samples at t = 0 and t = 4 s only
    intruder_at = np.array(pos[0]) + np.array([[0.0], [4.0]]) * np.array(vel[0])
    assert np.all(np.linalg.norm(samples - intruder_at, axis=1) > cfg.d_min_m)
    assert seg.event[0] == COLLISION
    assert seg.min_sep[0] < 1.0
    assert seg.t_closest[0] == pytest.approx(2.0, abs=0.01)


def test_closest_approach_matches_dense_sampling():
    cfg = PlannerConfig(x_bounds=(-5000, 5000), y_bounds=(-5000, 5000))
    model = EncounterModel(cfg)
    rng = np.random.default_rng(3)
    for _ in range(20):
        own = Ownship(0.0, 0.0, 120.0, rng.uniform(12, 30), rng.uniform(0, 2 * np.pi))
        action = int(rng.integers(9))
        pos = np.c_[rng.uniform(-150, 150, (3, 2)), rng.uniform(100, 140, 3)]
        vel = np.c_[rng.uniform(-30, 30, (3, 2)), np.zeros(3)]
        seg = fly_one(model, own, action, (4000, 4000, 120), 4.0, pos, vel, cull=False, exact=True)
        if seg.event[0] != NONE:
            continue  # the separation stops counting at the event
        # Dense reference: the ownship's arc sampled every 5 ms by the same model.
        fine = EncounterModel(PlannerConfig(**{**cfg.__dict__, "substep_s": 0.005}))
        dense = fly_one(fine, own, action, (4000, 4000, 120), 4.0)
        t = np.linspace(0.0, 4.0, dense.samples.shape[1])
        intr = pos[None] + t[:, None, None] * vel[None]
        d = np.linalg.norm(dense.samples[0][:, None] - intr, axis=2).min()
        assert seg.min_sep[0] == pytest.approx(d, abs=0.25)


def test_coordinated_turn_closes_a_circle():
    cfg = PlannerConfig(
        bank_step_deg=30.0,
        roll_rate_limit_deg_s=1e6,
        x_bounds=(-1e4, 1e4),
        y_bounds=(-1e4, 1e4),
    )
    model = EncounterModel(cfg)
    v = 20.0
    radius = v**2 / (G * math.tan(math.radians(30.0)))
    period = 2 * math.pi * radius / v
    seg = fly_one(model, Ownship(0.0, 0.0, 120.0, v, 0.0), RIGHT_HOLD, (0, 0, 120), period)
    xy = seg.samples[0, :, :2]
    np.testing.assert_allclose(xy[-1], [0.0, 0.0], atol=1e-6)
    # A right turn from north: centre at (radius, 0), every sample on the circle.
    np.testing.assert_allclose(np.linalg.norm(xy - [radius, 0.0], axis=1), radius, rtol=1e-9)
    assert seg.end[0, 4] == pytest.approx(0.0, abs=1e-9) or seg.end[0, 4] == pytest.approx(
        2 * math.pi, abs=1e-9
    )


def test_roll_rate_limits_the_bank():
    cfg = PlannerConfig(roll_rate_limit_deg_s=5.0)  # slow: a 10 deg step takes 2 s
    model = EncounterModel(cfg)
    seg = fly_one(model, Ownship(1000, 1000, 120, 20, 0.0), RIGHT_HOLD, (1000, 1900, 120), 1.0)
    assert seg.end[0, 6] == pytest.approx(math.radians(10.0))  # the command moved a step
    assert seg.end[0, 5] == pytest.approx(math.radians(5.0))  # the bank only half-way
    later = fly_one(model, Ownship(1000, 1000, 120, 20, 0.0), RIGHT_HOLD, (1000, 1900, 120), 4.0)
    assert later.end[0, 5] == later.end[0, 6] == pytest.approx(math.radians(10.0))


def test_speed_limits_and_altitude_rate():
    cfg = PlannerConfig(speed_mps=(12.0, 30.0), accel_mps2=1.0, climb_rate_mps=2.5)
    model = EncounterModel(cfg)
    seg = fly_one(model, Ownship(1000, 1000, 120, 28.5, 0.0), FASTER, (1000, 1900, 100), 4.0)
    assert seg.end[0, 3] == pytest.approx(30.0)  # clamped at the top speed
    assert seg.end[0, 2] == pytest.approx(110.0)  # 4 s at 2.5 m/s towards 100 m
    slow = fly_one(model, Ownship(1000, 1000, 120, 13.0, 0.0), SLOWER, (1000, 1900, 120), 4.0)
    assert slow.end[0, 3] == pytest.approx(12.0)


def test_ownship_air_is_the_steady_wind_plus_the_gust():
    """Ground velocity less air velocity: exactly the steady wind where the ground velocity is
    air velocity plus that wind (the kinematic world, also after many turns of heading), the
    gust on top of it otherwise (in turbulent air), and the wind alone when the ground velocity
    is unknown or the air is steady (then the difference is sideslip and climb, not air)."""
    cfg = PlannerConfig(wind_mps=(3.0, -2.0), gusts=True)
    psi = 0.3 + 40 * math.pi  # an unwrapped heading, as the kinematic world integrates it
    ground = (20 * math.sin(psi) + 3.0, 20 * math.cos(psi) - 2.0)
    heading = psi % (2 * math.pi)  # what the ownship's attitude reports
    assert ownship_air(Ownship(0, 0, 120, 20, heading, ground_velocity=ground), cfg) == (3.0, -2.0)
    assert ownship_air(Ownship(0, 0, 120, 20, heading), cfg) == (3.0, -2.0)
    gusty = (ground[0] + 1.5, ground[1] - 0.7)
    air = ownship_air(Ownship(0, 0, 120, 20, heading, ground_velocity=gusty), cfg)
    assert air == pytest.approx((4.5, -2.7), abs=1e-9)
    steady = PlannerConfig(wind_mps=(3.0, -2.0))
    own = Ownship(0, 0, 120, 20, heading, ground_velocity=gusty)
    assert ownship_air(own, steady) == (3.0, -2.0)


def test_the_ownship_drifts_with_its_air_and_the_intruders_keep_the_wind():
    """carry_ownship moves the ownship's paths by the air's motion, and with them what it
    meets; the intruders' tracks (over the ground already) stay where they were."""
    cfg = PlannerConfig(wind_mps=(1.0, 0.0))
    still, carried = EncounterModel(cfg), EncounterModel(cfg)
    carried.carry_ownship((3.0, -1.0))  # a 2 m/s east, 1 m/s south gust on the wind
    own = Ownship(1000, 1000, 120, 20, 0.0)
    a = fly_one(still, own, HOLD, (1000, 1900, 120), 4.0)
    b = fly_one(carried, own, HOLD, (1000, 1900, 120), 4.0)
    assert b.end[0, :2] - a.end[0, :2] == pytest.approx([8.0, -4.0])  # the gust for 4 s
    pos, vel = np.array([[1000.0, 1300.0, 120.0]]), np.array([[5.0, -10.0, 0.0]])
    assert np.array_equal(still.predict(pos, vel, 4.0).pos, carried.predict(pos, vel, 4.0).pos)
    # an intruder hovering 49.5 m above a point 9 m east, 4 m south of the still-air path's
    # end: missed in still air by 50.3 m (d_min 50 m), met at 49.5 m by the ownship its gust
    # carries there
    wait = [[a.end[0, 0] + 9.0, a.end[0, 1] - 4.0, 120.0 + 49.5]]
    goal, hover = (1000, 1900, 120), [[0.0, 0.0, 0.0]]
    missed = fly_one(still, own, HOLD, goal, 4.0, pos=wait, vel=hover, exact=True)
    assert missed.event[0] == NONE and 50.0 < missed.min_sep[0] < 50.5
    hit = fly_one(carried, own, HOLD, goal, 4.0, pos=wait, vel=hover)
    assert hit.event[0] == COLLISION


def test_leaving_the_area_and_reaching_the_goal_are_events():
    model = EncounterModel(PlannerConfig())
    out = fly_one(model, Ownship(1990, 1000, 120, 20, math.pi / 2), HOLD, (1000, 1000, 120), 4.0)
    assert out.event[0] == OUT_OF_BOUNDS
    # x = 2000 exactly at 0.5 s is still inside; the sub-step from 0.5 s leaves.
    assert out.t_event[0] == pytest.approx(0.5)
    # The goal lies on the path, reached between samples and passed again.
    goal = fly_one(model, Ownship(1000, 1000, 120, 20, 0.0), HOLD, (1000, 1045, 120), 4.0)
    assert goal.event[0] == GOAL


def test_culling_and_sampling_never_change_the_answer():
    """fly_all_actions (memoised, culled, sampled when clear) against the exact reference."""
    cfg = PlannerConfig()
    model = EncounterModel(cfg)
    rng = np.random.default_rng(11)
    goal = np.array([1000.0, 1000.0, 100.0])
    checked_close = 0
    for _ in range(200):
        n = 20
        pos = np.c_[rng.uniform(0, 2000, (n, 2)), rng.uniform(100, 140, n)]
        heading = rng.uniform(0, 2 * np.pi, n)
        speed = rng.uniform(15, 30, n)
        vel = np.c_[speed * np.sin(heading), speed * np.cos(heading), np.zeros(n)]
        track = model.predict(pos, vel, 4.0)
        own = Ownship(
            *rng.uniform(100, 1900, 2), 120.0, rng.uniform(12, 30), rng.uniform(0, 2 * np.pi)
        )
        state = ownship_state(own)
        fast = model.fly_all_actions(state, goal, 4.0, track)
        exact = model.fly(
            np.repeat(state[None], 9, 0), np.arange(9), goal, 4.0, track, cull=False, exact=True
        )
        np.testing.assert_array_equal(fast.event, exact.event)
        np.testing.assert_allclose(fast.end, exact.end, rtol=0, atol=1e-5)  # memo keys: 1e-6 m/s
        tol = 1e-5  # the memo computes from its rounded key
        assert np.all(fast.min_sep >= exact.min_sep - tol)
        close = exact.min_sep < cfg.d_min_m  # conflicts are always measured exactly
        np.testing.assert_allclose(fast.min_sep[close], exact.min_sep[close], atol=tol)
        far = np.isfinite(fast.min_sep) & ~close
        bound = 32.0**2 / (8 * exact.min_sep[far])  # L^2 / (8 d), L <= (30 + 30) * 0.5 + climb
        assert np.all(fast.min_sep[far] - exact.min_sep[far] <= bound + tol)
        checked_close += int(close.sum())
    assert checked_close > 0  # the sample did exercise near conflicts


def test_memo_does_not_change_results():
    cfg = PlannerConfig()
    goal = np.array([1500.0, 1500.0, 120.0])
    track = Track.of(np.zeros((9, 0, 3)))
    state = ownship_state(Ownship(500.3, 700.1, 120.0, 19.37, 0.4, bank=0.1745, phi=0.05))
    cold = EncounterModel(cfg).fly_all_actions(state, goal, 4.0, track)
    warm_model = EncounterModel(cfg)
    for v in (12.0, 19.37, 25.0):
        warm_model.fly_all_actions(
            state * [1, 1, 1, 0, 1, 1, 1, 1] + [0, 0, 0, v, 0, 0, 0, 0], goal, 4.0, track
        )
    warm = warm_model.fly_all_actions(state, goal, 4.0, track)
    np.testing.assert_array_equal(cold.end, warm.end)


def test_fly_end_and_the_batch_memo_give_flys_bits():
    """The kinematic world moves the ownship with fly_end and the traffic with
    fly_commanded, asking the same batches again and again: the memoised answers and the
    event-free end must be fly's own numbers, to the bit, whatever was asked before."""
    cfg = PlannerConfig()
    goal = np.array([1500.0, 1500.0, 140.0])
    states = np.array([
        ownship_state(Ownship(500.3, 700.1, 120.0, 19.37, 0.4, bank=0.1745, phi=0.05)),
        ownship_state(Ownship(900.0, 100.0, 130.0, 24.0, 2.0, bank=-0.3, phi=-0.1)),
    ])
    actions = np.array([RIGHT_HOLD, SLOWER])
    track = Track.of(np.zeros((3, 0, 3)))
    fresh = EncounterModel(cfg).fly(states, actions, goal, 1.0, track, cull=False).end
    warm = EncounterModel(cfg)
    for _ in range(3):  # the second and third come from the memo
        np.testing.assert_array_equal(warm.fly_end(states, actions, goal, 1.0), fresh)
        np.testing.assert_array_equal(warm.fly(states, actions, goal, 1.0, track).end, fresh)
    cmd = np.array([0.2, -0.4])
    once = EncounterModel(cfg).fly_commanded(states, cmd, 1.0)
    for _ in range(2):
        again = warm.fly_commanded(states, cmd, 1.0)
        for a, b in zip(again, once, strict=True):
            np.testing.assert_array_equal(a, b)
        np.testing.assert_array_equal(warm.fly_commanded(states, cmd, 1.0, samples=False)[1],
                                      once[1])  # fmt: skip
    # a different speed band is a different motion: the memo must not answer for it
    warm.hold_speed_band((23.5, 30.0))
    banded = EncounterModel(cfg)
    banded.hold_speed_band((23.5, 30.0))
    slowed = banded.fly_end(states, actions, goal, 1.0)
    assert fresh[1, 3] < slowed[1, 3] == 23.5  # the band's floor stops the slowing
    np.testing.assert_array_equal(warm.fly_end(states, actions, goal, 1.0), slowed)


def test_children_placed_one_at_a_time_match_the_vectorised_placement():
    """The tree search places a child it goes on from in plain Python, and all of them at
    once when the tree is finished: both must be the state ``fly`` computes."""
    cfg = PlannerConfig()
    model = EncounterModel(cfg)
    rng = np.random.default_rng(3)
    goal = np.array([1500.0, 400.0, 100.0])
    track = Track.of(np.zeros((9, 0, 3)))
    blocks, states = [], []
    for _ in range(20):
        own = Ownship(
            *rng.uniform(100, 1900, 2),
            rng.uniform(100, 140),
            rng.uniform(12, 30),
            rng.uniform(0, 2 * np.pi),
            bank=float(rng.choice([-0.35, 0.0, 0.175])),
        )
        state = ownship_state(own)
        placed, seg = model.expand(state.tolist(), goal, 4.0, track)
        assert seg.end is None
        exact = model.fly(np.repeat(state[None], 9, 0), np.arange(9), goal, 4.0, track)
        one_by_one = np.array([placed.state(a) for a in range(9)])
        np.testing.assert_allclose(one_by_one, exact.end, rtol=0, atol=1e-5)
        blocks.append(placed)
        states.append(one_by_one)
    np.testing.assert_allclose(place_children(blocks), np.concatenate(states), rtol=0, atol=1e-9)


def test_track_shape_is_checked():
    model = EncounterModel(PlannerConfig())
    with pytest.raises(ValueError, match="sub-steps"):
        model.fly_all_actions(
            ownship_state(Ownship(1000, 1000, 120, 20, 0.0)),
            np.array([0.0, 0.0, 120.0]),
            4.0,
            Track.of(np.zeros((3, 1, 3))),
        )


def test_indexed_track_finds_every_intruder_a_plain_test_finds():
    rng = np.random.default_rng(5)
    model = EncounterModel(PlannerConfig())
    n = 30
    pos = np.c_[rng.uniform(0, 2000, (n, 2)), rng.uniform(100, 140, n)]
    vel = np.c_[rng.uniform(-30, 30, (n, 2)), np.zeros(n)]
    indexed = model.predict(pos, vel, 4.0)
    plain = model.predict(pos, vel, 4.0, index=False)
    assert indexed.index_distance > 0 and not plain.index_distance
    assert not indexed.cells  # filed when first asked (the compiled search never asks)
    found = 0
    for _ in range(2000):
        centre = np.r_[rng.uniform(-200, 2200, 2), rng.uniform(90, 150)]
        distance = rng.uniform(0, 1.2 * indexed.index_distance)  # beyond: the plain test
        expected = np.flatnonzero(
            np.linalg.norm(plain.centre - centre, axis=1) <= distance + plain.radius
        )
        np.testing.assert_array_equal(np.sort(indexed.near(centre, distance)), expected)
        np.testing.assert_array_equal(plain.near(centre, distance), expected)
        found += expected.size
    assert found > 100
    assert indexed.cells and not plain.cells


def test_fly_levels_equals_flying_each_level():
    cfg = PlannerConfig()
    model = EncounterModel(cfg)
    rng = np.random.default_rng(8)
    n = 12
    pos = np.c_[rng.uniform(600, 1400, (n, 2)), rng.uniform(110, 130, n)]
    vel = np.c_[rng.uniform(-25, 25, (n, 2)), np.zeros(n)]
    tracks = [model.predict(pos, vel, 4.0, t0=4.0 * d) for d in range(3)]
    states = np.array(
        [
            ownship_state(Ownship(*rng.uniform(800, 1200, 2), 120, 20, rng.uniform(0, 6)))
            for _ in range(6)
        ]
    )
    actions = rng.integers(0, 9, 6)
    levels = np.array([0, 2, 1, 1, 0, 2])
    goal = np.array([1000.0, 1000.0, 110.0])
    both = model.fly_levels(states, actions, levels, goal, 4.0, tracks)
    for b in range(6):
        one = model.fly(
            states[b : b + 1],
            actions[b : b + 1],
            goal,
            4.0,
            tracks[levels[b]],
            cull=False,
            exact=True,
        )
        for name in ("end", "min_sep", "closest", "t_closest", "event"):
            np.testing.assert_allclose(getattr(both, name)[b], getattr(one, name)[0], atol=1e-9)


def test_tracks_of_all_levels_in_one_batch_are_each_level_predicted_alone():
    """predict_levels builds the tree levels' tracks in one batch (Track.levels): each is the
    track predict gives that level alone, to the bit (margin and sigma included)."""
    cfg = PlannerConfig(intruder_model="reachable", risk="probability")
    model = EncounterModel(cfg)
    rng = np.random.default_rng(3)
    n = 10
    pos = np.c_[rng.uniform(0, 2000, (n, 2)), rng.uniform(100, 140, n)]
    vel = np.c_[rng.uniform(-25, 25, (n, 2)), np.zeros(n)]
    turn = rng.uniform(-0.1, 0.1, n)
    margin = intruder_margin(cfg, vel, turn, np.full(n, 5.0), np.full(n, 2.0))
    sigma = track_sigma(cfg, n, np.full(n, 5.0), np.full(n, 2.0))
    starts = [0.0, 4.0, 8.0, 12.0]
    batch = model.predict_levels(pos, vel, 4.0, starts, turn_rate=turn, margin=margin,
                                 sigma=sigma)  # fmt: skip
    assert batch[-1].margin is not None and batch[-1].sigma is not None
    for t0, track in zip(starts, batch, strict=True):
        alone = model.predict_levels(pos, vel, 4.0, [t0], turn_rate=turn, margin=margin,
                                     sigma=sigma)[0]  # fmt: skip
        for name in ("pos", "xy", "h", "centre", "radius", "margin", "sigma"):
            np.testing.assert_array_equal(getattr(track, name), getattr(alone, name))
        assert (track.step_max, track.index_distance) == (alone.step_max, alone.index_distance)


def test_the_search_terminal_codes_are_read_back_as_the_outcome_enum():
    from uavxai.avoidance.model import OUTCOME_NAMES, TIMEOUT, terminal_value
    from uavxai.vocabulary import Outcome

    assert NONE == 0 and OUTCOME_NAMES[NONE] == ""
    for code, outcome in ((GOAL, Outcome.GOAL), (COLLISION, Outcome.COLLISION),
                          (OUT_OF_BOUNDS, Outcome.OUT_OF_BOUNDS), (TIMEOUT, Outcome.TIMEOUT)):
        assert OUTCOME_NAMES[code] == outcome.value  # fmt: skip
    # eq 14's values by outcome: goal 1, collision and leaving the map 0, time-out 0.1
    assert [terminal_value(o) for o in ("goal", "collision", "out_of_bounds", "timeout")] == [
        1.0, 0.0, 0.0, 0.1]  # fmt: skip
