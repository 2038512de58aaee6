"""Walking users: random waypoint stays in the region, at walking speed, pauses, is seeded."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.comms.channel import draw_users
from uavxai.comms.mobility import MOBILITY_STREAM, UserMobility
from uavxai.errors import UserError
from uavxai.scenario import default_scenario

REGION = {"x": [750.0, 1250.0], "y": [750.0, 1250.0]}
SPEED = (0.5, 1.5)
PAUSE = (0.0, 30.0)


def walkers(seed: int = 7, k: int = 10, **kw) -> UserMobility:
    xy = np.random.default_rng(seed).uniform(750.0, 1250.0, size=(k, 2))
    opts = {"model": "random_waypoint", "speed_mps": SPEED, "pause_s": PAUSE, "seed": seed}
    return UserMobility(xy, REGION, **{**opts, **kw})


def test_users_stay_in_region_and_walk_at_bounded_speed():
    m = walkers()
    dt = 0.5
    path = m.path(dt, 4000)  # 2000 s: dozens of legs per user
    assert path.shape == (4001, 10, 3)
    assert np.all(path[..., 2] == 0.0)
    xy = path[..., :2]
    assert np.all(xy >= 750.0) and np.all(xy <= 1250.0)
    step = np.linalg.norm(np.diff(xy, axis=0), axis=-1)  # (4000, K)
    # Never faster than the fastest walker (a step may be shorter: a pause or a waypoint
    # corner inside the interval), and the users really went places.
    assert step.max() <= SPEED[1] * dt + 1e-9
    assert np.all(np.ptp(xy, axis=0) > 100.0)
    # Steps with no pause or corner inside are at a speed within bounds, and both ends of
    # the range are used (leg speeds are drawn, not fixed).
    full = step[step > 1e-6]
    straight = full[full > SPEED[0] * dt - 1e-9]
    assert len(straight) > 0.8 * len(full)
    assert straight.min() < 0.6 * dt and straight.max() > 1.4 * dt


def test_pauses_happen_and_last_within_bounds():
    m = walkers(k=5)
    dt = 1.0
    stands, seen_pause = [], False
    for _ in range(3000):
        m.advance(dt)
        paused = m.paused
        seen_pause |= bool(paused.any())
        stands.append(paused)
        # A paused user has zero velocity, a walking one a speed within bounds.
        v = np.linalg.norm(m.velocities, axis=1)
        assert np.all(v[paused] == 0.0)
        assert np.all((v[~paused] >= SPEED[0] - 1e-12) & (v[~paused] <= SPEED[1] + 1e-12))
    assert seen_pause
    stands = np.array(stands)
    # Each user stood still a sizeable fraction of the time: mean pause 15 s against legs of
    # about 250 m / 1 m/s, i.e. roughly 5 % (not 0, not most of the time).
    share = stands.mean(axis=0)
    assert np.all(share > 0.01) and np.all(share < 0.5)
    # No run of paused samples is longer than the longest pause (30 s) plus one step.
    for j in range(stands.shape[1]):
        run = longest = 0
        for s in stands[:, j]:
            run = run + 1 if s else 0
            longest = max(longest, run)
        assert longest * dt <= PAUSE[1] + dt


def test_no_pause_range_means_never_standing():
    m = walkers(pause_s=(0.0, 0.0))
    for _ in range(500):
        m.advance(2.0)
        assert not m.paused.any()


def test_same_seed_same_paths_whatever_the_step():
    a = walkers(seed=3).path(0.1, 6000)[::10]  # 600 s logged at 10 Hz, kept at 1 Hz
    b = walkers(seed=3).path(1.0, 600)
    np.testing.assert_allclose(a, b, atol=1e-6)  # per-user streams: dt does not matter
    c = walkers(seed=4).path(1.0, 600)
    assert np.abs(b - c).max() > 10.0


def test_a_users_path_does_not_depend_on_the_others():
    xy = np.random.default_rng(0).uniform(750.0, 1250.0, size=(4, 2))
    full = UserMobility(xy, REGION, "random_waypoint", seed=11).path(1.0, 300)
    # The streams are spawned per index, so the first users of a larger crowd walk the same.
    more = np.vstack([xy, [[1000.0, 1000.0]]])
    crowd = UserMobility(more, REGION, "random_waypoint", seed=11).path(1.0, 300)
    np.testing.assert_allclose(crowd[:, :4], full)


def test_static_never_moves():
    xy = np.array([[800.0, 900.0], [1200.0, 760.0]])
    m = UserMobility(xy, REGION, "static", seed=1)
    assert not m.moving
    for _ in range(100):
        pos = m.advance(5.0)
    np.testing.assert_array_equal(pos[:, :2], xy)
    assert np.all(m.velocities == 0.0)
    assert m.t == pytest.approx(500.0)


def test_user_outside_the_region_walks_in_and_stays():
    m = UserMobility([[0.0, 0.0]], REGION, "random_waypoint", speed_mps=(1.0, 1.0), seed=2)
    path = m.path(10.0, 600)[:, 0, :2]
    inside = np.all((path >= 750.0) & (path <= 1250.0), axis=1)
    first = int(np.argmax(inside))
    assert first > 0 and inside[first:].all()


def test_from_scenario_defaults_to_static_and_reads_the_config():
    sc = default_scenario()
    m = UserMobility.from_scenario(sc)
    assert m.model == "static"
    np.testing.assert_array_equal(m.positions, draw_users(sc))

    walking = default_scenario(seed=5, comms={"users": {"mobility": {
        "model": "random_waypoint", "speed_mps": [1.0, 1.2], "pause_s": [5, 6]}}})  # fmt: skip
    users = draw_users(sc)
    m = UserMobility.from_scenario(walking, users)
    assert m.model == "random_waypoint"
    assert m.speed_mps == (1.0, 1.2) and m.pause_s == (5.0, 6.0)
    again = UserMobility(
        users, REGION, "random_waypoint", (1.0, 1.2), (5, 6), seed=[5, MOBILITY_STREAM]
    )
    np.testing.assert_array_equal(m.path(1.0, 50), again.path(1.0, 50))


def test_from_scenario_reads_the_schema_and_scalars_are_fixed_values():
    mobility = {"model": "random_waypoint", "speed_mps": 1.2, "pause_s": 4.0}
    sc = default_scenario(seed=3, comms={"users": {"mobility": mobility}})
    m = UserMobility.from_scenario(sc)
    assert (m.model, m.speed_mps, m.pause_s) == ("random_waypoint", (1.2, 1.2), (4.0, 4.0))
    step = np.linalg.norm(np.diff(m.path(0.5, 2000)[..., :2], axis=0), axis=-1)
    walking = step[step > 1e-9]
    # A fixed speed: every step with no corner or pause inside is exactly 0.6 m.
    assert np.mean(np.isclose(walking, 0.6, rtol=1e-9)) > 0.95
    assert walking.max() <= 0.6 + 1e-9
    # Standing still as "static" with a speed of 0 in the file is not an error.
    zero = default_scenario(comms={"users": {"mobility": {"model": "static", "speed_mps": 0}}})
    assert not UserMobility.from_scenario(zero).moving


def test_generator_seed_is_reproducible():
    xy = [[1000.0, 1000.0]]
    a = UserMobility(xy, REGION, "random_waypoint", seed=np.random.default_rng(9)).path(1, 99)
    b = UserMobility(xy, REGION, "random_waypoint", seed=np.random.default_rng(9)).path(1, 99)
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize(
    ("kw", "field"),
    [
        ({"model": "levy_walk"}, "model"),
        ({"speed_mps": (0.0, 1.0)}, "speed_mps"),
        ({"speed_mps": 0.0}, "speed_mps"),
        ({"speed_mps": (2.0, 1.0)}, "speed_mps"),
        ({"pause_s": (-1.0, 1.0)}, "pause_s"),
        ({"pause_s": "long"}, "pause_s"),
    ],
)
def test_bad_config_names_the_field(kw, field):
    with pytest.raises(UserError, match=f"mobility.{field}"):
        walkers(**kw)


def test_bad_step_and_region_are_user_errors():
    with pytest.raises(UserError, match="time step"):
        walkers().advance(-1.0)
    with pytest.raises(UserError, match="region"):
        UserMobility([[0.0, 0.0]], {"x": [5, 5], "y": [0, 1]}, "static")
