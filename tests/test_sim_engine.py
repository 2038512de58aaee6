"""The episode engine: one loop for `run` and `evaluate`, a clock in ticks, one judge."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from engine_runs import run_and_evaluate

from uavxai.errors import UserError
from uavxai.scenario import default_scenario
from uavxai.sim.build import fly, run_kinematic
from uavxai.sim.clock import Clock
from uavxai.sim.episode import Observer
from uavxai.sim.judge import Judge
from uavxai.sim.kinematic import KinematicWorld
from uavxai.sim.spec import episode_spec
from uavxai.vocabulary import Outcome

EQ = {
    "name": "engine-eq",
    "seed": 3,
    "intruders": {"count": 8},
    "comms": {"fading": "none"},
    "service": {"planner": "grid", "steps": 10, "platform": "hover"},  # the fast exact grid
    "avoidance": {"max_steps": 80},
    "mission": {"service_s": 0},  # the paper's transit episode, as campaigns fly it
    "log": {"rerun": False},
}


def test_run_and_evaluate_fly_the_same_episode(tmp_path: Path) -> None:
    """`uavxai run` (MAVLink bytes through the bridge) and `uavxai evaluate --dynamics jsbsim`
    (direct to the autopilot): same outcome, steps and minimum separation to 1 mm."""
    run, ev = run_and_evaluate(tmp_path, EQ)
    assert run["bridge"]["commands"] >= 2 * run["steps"]  # really through MAVLink
    assert (ev["outcome"], int(ev["steps"])) == (run["outcome"], run["steps"])
    assert float(ev["min_separation_m"]) == pytest.approx(run["min_separation_m"], abs=1e-3)


def test_clock_counts_whole_ticks_and_refuses_rates_that_do_not_divide() -> None:
    c = Clock.from_scenario(default_scenario("c"))
    assert (c.sample_ticks, c.decision_ticks, c.samples_per_decision) == (12, 120, 10)
    # the scenario schema refuses these already (so that `validate` says it)
    with pytest.raises(UserError, match="trajectory_hz"):
        default_scenario("c", dynamics={"rate_hz": 100, "trajectory_hz": 30})
    with pytest.raises(UserError, match="decision_period_s"):
        default_scenario("c", avoidance={"decision_period_s": 1.05})
    # one rule: a scenario copied past the schema's checks meets the same words at the clock
    sc = default_scenario("c")
    bad = sc.model_copy(update={"dynamics": sc.dynamics.model_copy(update={"rate_hz": 100.0,
                                                                          "trajectory_hz": 30.0})})
    with pytest.raises(UserError, match=r"rate_hz \(100\) must be a whole multiple of "
                                        r"dynamics.trajectory_hz \(30\).*docs/scenario.md"):
        Clock.from_scenario(bad)


def test_judge_order_failure_collision_bounds_goal() -> None:
    sc = default_scenario("j")
    judge = Judge(sc.world, 50.0, (1000, 1000, 120), 50.0)
    world = KinematicWorld(sc, intruders=[])
    s = world.state()
    assert judge.judge(s, 10.0, "NaN in ownship state") is Outcome.FDM_FAILURE
    assert judge.judge(s, 10.0, None) is Outcome.COLLISION
    assert judge.judge(s, 100.0, None) is None


class _Count(Observer):
    def __init__(self) -> None:
        self.events: dict[str, int] = dict.fromkeys(("start", "decision", "sample", "end"), 0)

    def on_start(self, ep) -> None:
        self.events["start"] += 1

    def on_decision(self, ep, event) -> None:
        self.events["decision"] += 1

    def on_sample(self, ep, state) -> None:
        self.events["sample"] += 1

    def on_end(self, ep, summary) -> None:
        self.events["end"] += 1
        summary["counted"] = True


def test_an_output_is_an_observer_and_sees_every_event() -> None:
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig

    sc = default_scenario("obs", avoidance={"max_steps": 7}, seed=4)
    count = _Count()
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    r = fly(
        episode_spec(sc, goal=(1900, 1900, 120), dynamics="kinematic", intruders=[]),
        planner,
        observers=[count],
    )
    assert r.outcome is Outcome.TIMEOUT and r.steps == 7
    assert count.events == {"start": 1, "decision": 7, "sample": 70, "end": 1}
    assert r.summary["counted"] and r.summary["outcome"] == "timeout"


class _Positions(Observer):
    """The ownship's position at every sample; Ctrl-C after ``stop_after`` samples."""

    def __init__(self, stop_after: int | None = None) -> None:
        self.pos: list[np.ndarray] = []
        self.stop_after = stop_after

    def on_sample(self, ep, state) -> None:
        self.pos.append(state.pos[0].copy())
        if len(self.pos) == self.stop_after:
            raise KeyboardInterrupt


@pytest.mark.parametrize("stop_after", [None, 15])
def test_throughput_integrates_every_sample_flown(stop_after: int | None) -> None:
    """The in-flight throughput evaluates the channel a period at a time: it still counts
    every sample, in an episode cut short in the middle of a period too."""
    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.comms.channel import Channel
    from uavxai.sim.observers import Throughput

    sc = default_scenario("tput", seed=4, avoidance={"max_steps": 4}, comms={"fading": "none"})
    users = np.array([[200.0, 300.0, 0.0], [900.0, 400.0, 0.0], [500.0, 1200.0, 0.0]])
    channel = Channel.from_scenario(sc, users=users)
    power = channel.equal_power()
    seen, tput = _Positions(stop_after), Throughput(channel, power)
    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    # the throughput first: it has seen a sample when the other observer interrupts
    r = fly(
        episode_spec(sc, goal=(1900, 1900, 120), dynamics="kinematic", intruders=[]),
        planner,
        observers=[tput, seen],
    )
    assert len(seen.pos) == (40 if stop_after is None else 15)
    assert r.outcome is (Outcome.TIMEOUT if stop_after is None else Outcome.INTERRUPTED)
    rates = [float(channel.sum_rate_bps(p, power)) for p in seen.pos]
    assert r.summary["throughput_in_flight_bits"] == pytest.approx(sum(rates) * 0.1, rel=1e-12)
    assert len(set(rates)) > 1  # the ownship moved: each sample has its own rate


def test_kinematic_world_flies_the_commanded_turn() -> None:
    """A 30 deg bank at 20 m/s turns at g tan(phi) / V once the roll has settled."""
    sc = default_scenario("turn")
    world = KinematicWorld(sc, intruders=[])
    world.command_ownship(bank_cmd_rad=np.radians(30.0), accel_cmd_mps2=0.0, alt_target_m=120.0)
    world.advance(3.0)
    psi0, t0 = world.state().att[0, 2], world.t
    world.advance(4.0)
    rate = (world.state().att[0, 2] - psi0) / (world.t - t0)
    assert rate == pytest.approx(9.80665 * np.tan(np.radians(30)) / 20.0, rel=1e-3)


def test_kinematic_episode_is_reproducible_and_ends_in_a_known_outcome() -> None:
    sc = default_scenario("k", ownship={"goal": [1000, 1000, 120]})
    a = run_kinematic("mcts_fast", sc, 11, 15)
    b = run_kinematic("mcts_fast", sc, 11, 15)
    assert (a.outcome, a.steps, a.min_separation_m) == (b.outcome, b.steps, b.min_separation_m)
    assert a.outcome in {o.value for o in Outcome}


def test_the_planner_believes_what_the_adsb_frames_on_the_link_carry(tmp_path: Path) -> None:
    """`uavxai run` with ADS-B surveillance: the reports the tracker ingests are the ones
    decoded from ADSB_VEHICLE frames, and a ground station on the link receives those same
    frames (noisy, not the truth)."""
    import socket

    from pymavlink import mavutil

    from uavxai.avoidance.planners import make_planner
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.sim.picture import Picture
    from uavxai.sim.run import mavlink_path

    gcs = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    gcs.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 1 << 22)
    gcs.bind(("127.0.0.1", 0))
    gcs.settimeout(0.0)
    port = gcs.getsockname()[1]
    sc = default_scenario("adsb", seed=2, avoidance={"max_steps": 8}, intruders={"count": 6})

    decoded: list = []

    class Grab(Observer):
        def on_start(self, ep) -> None:
            ep.picture.receiver.decoded = []  # heard before t = 0, not sent (the pre-roll)

        def on_sample(self, ep, state) -> None:
            link = ep.picture.receiver
            decoded.extend((r.id, round(r.pos[0], 2), round(r.pos[1], 2)) for r in link.decoded)
            link.decoded = []

    planner = make_planner("none", PlannerConfig.from_scenario(sc))
    r = fly(
        episode_spec(sc, goal=(1900, 1900, 120), dynamics="jsbsim"),
        planner,
        path=mavlink_path(sc, f"udpout:127.0.0.1:{port}"),
        observers=[Grab()],
    )
    assert r.steps == 8 and decoded
    mav = mavutil.mavlink.MAVLink(None)
    received = []
    while True:
        try:
            data = gcs.recv(65536)
        except BlockingIOError:
            break
        for m in mav.parse_buffer(data) or []:
            if m.get_type() == "ADSB_VEHICLE":
                received.append(m)
    frame = Picture(sc).frame
    on_link = set()
    for m in received:
        x, y, _ = frame.to_local(m.lat / 1e7, m.lon / 1e7, m.altitude / 1000.0)
        ident = f"intruder-{m.ICAO_address - 0xF00000}"
        on_link.add((ident, round(float(x), 2), round(float(y), 2)))
    assert set(decoded) <= on_link  # everything the planner decoded went out on the link
    assert len(received) >= len(decoded)


def test_judge_nmac_shortcut_by_separation_never_changes_the_answer() -> None:
    """The NMAC test skips the cylinder when the closest approach is beyond its corner; over
    random sample pairs (many near the cylinder's edge) the answer is the full test's."""
    from uavxai.dynamics.state import TrafficState

    judge = Judge(default_scenario("n").world, 50.0, None, 50.0)
    rng = np.random.default_rng(4)
    ids = ("ownship", *(f"intruder-{i}" for i in range(1, 9)))
    inside = 0
    for _ in range(400):
        p0 = rng.uniform(-200, 200, (9, 3))
        p1 = p0 + rng.uniform(-30, 30, (9, 3))
        z = np.zeros((9, 3))
        a = TrafficState(0.0, ids, p0, z, z, np.ones(9))
        b = TrafficState(0.1, ids, p1, z, z, np.ones(9))
        full = judge.nmac(a, b)
        assert judge.nmac(a, b, judge.separation(a, b)) == full
        inside += full
    assert 50 < inside < 350  # both answers were exercised


def _states(ids0, ids1, p0, p1):
    from uavxai.dynamics.state import TrafficState

    p0, p1 = np.array(p0, dtype=float), np.array(p1, dtype=float)
    z = np.zeros_like(p0)
    n = len(p0)
    return (TrafficState(0.0, ids0, p0, z, z, np.ones(n)),
            TrafficState(0.1, ids1, p1, z, z, np.ones(n)))  # fmt: skip


def test_a_replaced_row_restarts_only_its_own_pair_for_separation_and_nmac() -> None:
    """intruder-2 is replaced (persistent traffic) in the sample in which the ownship and
    intruder-1 pass through each other (200 m apart before and after): the pass-through is a
    collision and an NMAC (before, the NMAC test measured every row from now on any
    replacement: a collision but no NMAC). The newcomer stands now where the ownship was:
    it was not there then, so 200 m, not 0 m."""
    judge = Judge(default_scenario("r").world, 50.0, None, 50.0)
    prev, now = _states(("ownship", "intruder-1", "intruder-2"),
                        ("ownship", "intruder-1", "intruder-3"),
                        [(0, 0, 100), (200, 0, 100), (0, 900, 100)],
                        [(200, 0, 100), (0, 0, 100), (0, 0, 100)])  # fmt: skip
    assert judge.separation(prev, now) == pytest.approx(0.0, abs=1e-9)
    assert judge.nmac(prev, now) and judge.nmac(prev, now, judge.separation(prev, now))
    # without the pass-through, the newcomer alone: judged where it is, 200 m away
    prev, now = _states(("ownship", "intruder-1", "intruder-2"),
                        ("ownship", "intruder-1", "intruder-3"),
                        [(0, 0, 100), (900, 0, 100), (0, 900, 100)],
                        [(200, 0, 100), (900, 0, 100), (0, 0, 100)])  # fmt: skip
    assert judge.separation(prev, now) == pytest.approx(200.0)
    assert not judge.nmac(prev, now)
