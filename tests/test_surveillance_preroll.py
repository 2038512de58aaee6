"""The receiver's pre-roll (`surveillance.preroll_s`): it has been listening before t = 0, so
the planner's first picture already holds the traffic, and the reports carry on into the
flight without a double or a gap."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.sim.build import fly
from uavxai.sim.clock import Clock
from uavxai.sim.episode import Observer
from uavxai.sim.kinematic import KinematicWorld
from uavxai.sim.picture import Picture, Receiver
from uavxai.sim.spec import episode_spec
from uavxai.surveillance.adsb import (
    NACP_EPU_M,
    NACP_VEPU_M,
    R95_PER_SIGMA_2D,
    Report,
    SurveillanceConfig,
)
from uavxai.surveillance.tracker import Tracker, TrackerConfig

GOAL = (1000.0, 1000.0, 120.0)


class _First(Observer):
    """The first decision's picture and the truth it was taken from."""

    event = None

    def on_decision(self, ep, event) -> None:
        if self.event is None:
            self.event = event


def _first_picture(preroll_s: float, seed: int = 6):
    sc = default_scenario(
        "pre", seed=seed, intruders={"count": 12}, avoidance={"max_steps": 2},
        surveillance={"preroll_s": preroll_s},
    )  # fmt: skip
    first = _First()
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    fly(episode_spec(sc, goal=GOAL, dynamics="kinematic"), planner, observers=[first])
    return sc, first.event


def test_with_a_preroll_the_first_picture_holds_every_cooperative_intruder() -> None:
    """At t = 0 every intruder (all cooperative here) is tracked, with a velocity (not a
    position-only track), heard lately; its position within the NACp 95 % bounds of a single
    report (horizontal and vertical), and the tracks say how sure they are: their errors
    inside their own 95 % radii. "95 %": at most one of the twelve outside, and none beyond
    twice the bound."""
    sc, event = _first_picture(10.0)
    assert event.t == 0.0
    truth = event.truth
    beliefs = {b.id: b for b in event.intruders}
    assert set(beliefs) == set(truth.ids[1:])
    cfg = SurveillanceConfig.from_scenario(sc)
    epu, vepu = NACP_EPU_M[cfg.nacp], NACP_VEPU_M[cfg.nacp]
    ratios: dict[str, list[float]] = {"h": [], "v": [], "sigma_m": [], "sigma_v": []}
    for i, ident in enumerate(truth.ids[1:], start=1):
        b = beliefs[ident]
        assert b.sigma_v < TrackerConfig().init_vel_sigma_mps, ident  # it has a velocity
        assert b.age_s <= 1.0 / cfg.rate_hz + cfg.latency_s + 2.0, ident  # not coasting
        err_h = math.hypot(b.x - truth.pos[i, 0], b.y - truth.pos[i, 1])
        err_v = math.hypot(b.vx - truth.vel[i, 0], b.vy - truth.vel[i, 1])
        ratios["h"].append(err_h / epu)
        ratios["v"].append(abs(b.h - truth.pos[i, 2]) / vepu)
        ratios["sigma_m"].append(err_h / (R95_PER_SIGMA_2D * b.sigma_m))
        ratios["sigma_v"].append(err_v / (R95_PER_SIGMA_2D * b.sigma_v))
    for name, r in ratios.items():
        assert sum(x > 1.0 for x in r) <= 1 and max(r) <= 2.0, (name, r)


def test_without_a_preroll_the_first_picture_is_empty() -> None:
    """`preroll_s: 0` is the standing start: nothing heard yet at t = 0."""
    _, event = _first_picture(0.0)
    assert event.t == 0.0 and event.truth.n == 13
    assert event.intruders == []


class _Log(Receiver):
    """A receiver that also keeps every report it decoded: (id, measured, delivered)."""

    def __init__(self, scenario) -> None:
        super().__init__(scenario)
        self.log: list[tuple[str, float, float]] = []

    def receive(self, frames: bytes, onboard, t: float) -> None:
        super().receive(frames, onboard, t)
        self.log += [(r.id, r.t_measured, r.t_delivered) for r in self.decoded]


def test_reports_carry_on_across_t0_without_a_double_or_a_gap() -> None:
    """Without losses, every intruder's reports are measured exactly one period apart from
    the first heard in the pre-roll to the last in flight, t = 0 included: none twice, none
    missing; the pre-roll's are all delivered before t = 0 or at the live samples after."""
    sc = default_scenario(
        "gap", seed=4, intruders={"count": 8}, surveillance={"dropout": 0.0, "preroll_s": 5.0}
    )
    world = KinematicWorld(sc, seed=sc.seed)
    clock = Clock.from_scenario(sc)
    receiver = _Log(sc)
    picture = Picture(sc, receiver=receiver)
    state = world.state()
    picture.listen(state, clock)
    heard_before = len(receiver.log)
    picture.on_sample(None, state)  # type: ignore[arg-type] - the picture needs no episode
    for _ in range(50):  # 5 s of flight
        world.step(clock.sample_ticks)
        picture.on_sample(None, world.state())  # type: ignore[arg-type]
    assert heard_before > 0 and all(d < 0 for _, _, d in receiver.log[:heard_before])
    assert all(d >= 0 for _, _, d in receiver.log[heard_before:])
    period = 1.0 / sc.surveillance.rate_hz
    for ident in state.ids[1:]:
        measured = [m for i, m, _ in receiver.log if i == ident]
        assert measured[0] < -5.0 + period + 1e-6  # heard from the start of the pre-roll
        assert measured[-1] > 5.0 - period - sc.surveillance.latency_s - 1e-6
        np.testing.assert_allclose(np.diff(measured), period, atol=1e-6)


def test_the_preroll_is_seeded_and_the_companion_hears_it_alike() -> None:
    """The same seed gives the same picture at t = 0, to the bit, and a picture whose
    receiver is on the companion process (as `uavxai run` has it) hears the same pre-roll."""
    from uavxai.sim.companion import Companion

    sc = default_scenario("rx", seed=3, intruders={"count": 6})
    state = KinematicWorld(sc, seed=sc.seed).state()
    clock = Clock.from_scenario(sc)
    pictures = [Picture(sc), Picture(sc)]
    with Companion("mcts", PlannerConfig(), scenario=sc) as companion:
        pictures.append(Picture(sc, receiver=companion.receiver))
        for p in pictures:
            p.listen(state, clock)
            p.on_sample(None, state)  # type: ignore[arg-type] - the picture needs no episode
        first = pictures[0](state)
        assert len(first) == 6
        assert pictures[1](state) == first
        assert pictures[2](state) == first


def test_tracks_heard_before_t0_coast_and_drop_on_the_same_rule() -> None:
    """Negative times are times like any other: a track last measured at -7 s is still
    believed (coasting) 5.9 s later and dropped once its last report is over 6 s old."""
    cfg = SurveillanceConfig(dropout=0.0)
    tracker = Tracker()
    for t in (-9.0, -8.0, -7.0):
        pos = np.array([20.0 * (t + 9.0), 0.0, 120.0])
        vel = np.array([20.0, 0.0, 0.0])
        tracker.update(
            [Report("intruder-1", t, t + 0.5, pos, vel, cfg.sigma_pos, cfg.sigma_vel, "adsb")]
        )
    (b,) = tracker.beliefs(-1.1)
    assert b.age_s == pytest.approx(5.9) and b.x == pytest.approx(20.0 * 7.9, abs=1.0)
    assert tracker.beliefs(-0.9) == [] and tracker.dropped == ["intruder-1"]


def test_preroll_must_not_be_negative() -> None:
    with pytest.raises(UserError, match=r"surveillance\.preroll_s"):
        default_scenario("neg", surveillance={"preroll_s": -1})
    allowed = r"surveillance\.preroll_s' = -0\.5: Input should be greater than or equal to 0"
    with pytest.raises(UserError, match=allowed):
        SurveillanceConfig(preroll_s=-0.5)
