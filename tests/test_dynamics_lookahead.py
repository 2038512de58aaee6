"""The intruders flown ahead of the ownship while its next command is searched for
(`JSBSimWorld.lookahead`), and every aircraft flown its whole chunk at once
(`JSBSimWorld._integrate`), fly the same flight, to the bit, as the world in lockstep (every
executive one tick in turn): with turbulence, turning traffic, a loiter orbit, ownship
commands between periods, and an intruder lost in flight and replaced."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.dynamics.state import TrafficState
from uavxai.dynamics.world import JSBSimWorld
from uavxai.scenario import default_scenario

SAMPLE_TICKS = 12  # 10 Hz at the default 120 Hz
PERIOD_TICKS = 120  # one decision per second


def _scenario(count: int = 4):
    return default_scenario(
        "lookahead",
        seed=3,
        intruders={"count": count, "behaviour": "random_turns"},
        environment={"wind": {"speed_mps": 6.0, "from_deg": 200.0}, "turbulence": "moderate"},
    )


class LockstepWorld(JSBSimWorld):
    """The reference: every executive flies one tick in turn, as the world did before it
    flew each aircraft's chunk at once (issue 31)."""

    def _integrate(self, ticks: int) -> bool:
        for _ in range(ticks):
            for run in self._runs:
                run()
        return True


def _lose_control(w: JSBSimWorld, row: int) -> None:
    w.aircraft[row].fdm["ap/engaged"] = 0.0
    w.aircraft[row].fdm["fcs/aileron-cmd-norm"] = 1.0  # full aileron, no autopilot


def _fly(w: JSBSimWorld, periods: int, ahead: bool, lose: int | None = None) -> list:
    """Every sample's state; the ownship commanded at each period as a planner would."""
    states: list[TrafficState] = [w.state()]
    flown_ahead = 0
    for k in range(periods):
        if k == 2 and lose is not None:
            _lose_control(w, lose)
        if k == 4:
            s = w.state()
            w.command_orbit(s.pos[0, 0] + 150.0, s.pos[0, 1], 150.0)
        elif k % 3 == 0 and k < 4:
            w.command_ownship(bank_cmd_rad=0.3 * (-1) ** k, accel_cmd_mps2=0.5)
        if ahead:
            flown_ahead += w.lookahead(PERIOD_TICKS, SAMPLE_TICKS)
        for _ in range(PERIOD_TICKS // SAMPLE_TICKS):
            w.step(SAMPLE_TICKS)
            states.append(w.state())
            if w.failure():
                return states
    states.append(flown_ahead)
    return states


def _same(a: list, b: list) -> None:
    assert len(a) == len(b)
    for sa, sb in zip(a[:-1], b[:-1], strict=True):
        assert sa.t == sb.t and sa.ids == sb.ids
        for field in ("pos", "vel", "att", "airspeed"):
            np.testing.assert_array_equal(getattr(sa, field), getattr(sb, field))


def test_intruders_flown_ahead_give_the_lockstep_flight_to_the_bit() -> None:
    sc = _scenario()
    with LockstepWorld(sc) as lock, JSBSimWorld(sc) as ahead:
        a = _fly(lock, 8, ahead=False)
        b = _fly(ahead, 8, ahead=True)
        assert b[-1] == 8 * PERIOD_TICKS  # the intruders really flew ahead every period
        assert a[-1] == 0
        _same(a, b)
        assert lock.orbit is not None and ahead.orbit is not None


def test_an_intruder_lost_while_ahead_is_replaced_where_the_ownship_meets_it() -> None:
    sc = _scenario(count=2)
    with LockstepWorld(sc) as lock, JSBSimWorld(sc) as ahead:
        a = _fly(lock, 14, ahead=False, lose=1)
        b = _fly(ahead, 14, ahead=True, lose=1)
        assert lock.lost_intruders and lock.lost_intruders == ahead.lost_intruders
        # the others flew ahead every period, the wreck too until the ownship met it there
        assert b[-1] == 14 * PERIOD_TICKS
        _same(a, b)
        assert b[-2].ids[1] != "intruder-1"  # a newcomer flies in its row


def test_each_aircraft_flown_its_chunk_at_once_gives_the_lockstep_flight_to_the_bit() -> None:
    sc = _scenario(count=5)
    with LockstepWorld(sc) as lock, JSBSimWorld(sc) as chunked:
        a = _fly(lock, 6, ahead=False)
        b = _fly(chunked, 6, ahead=False)
        _same(a, b)
        lock.step(PERIOD_TICKS * 2 + 7)  # chunks cut at the pilots' instants, not samples
        chunked.step(PERIOD_TICKS * 2 + 7)
        _same([lock.state(), 0], [chunked.state(), 0])


def test_the_lookahead_stops_at_the_pilots_instant_and_states_only_at_kept_ticks() -> None:
    with JSBSimWorld(_scenario(count=2)) as w:
        w.step(SAMPLE_TICKS * 3)  # 0.3 s into the pilots' second
        assert w.lookahead(10 * PERIOD_TICKS, SAMPLE_TICKS) == PERIOD_TICKS - 3 * SAMPLE_TICKS
        assert w.lookahead(PERIOD_TICKS, SAMPLE_TICKS) == 0  # already ahead: nothing more
        with pytest.raises(RuntimeError, match="kept ticks"):
            w.step(5)  # between two kept ticks: the traffic check cannot see the intruders
        w.step(SAMPLE_TICKS - 5)
        assert w.state().t == pytest.approx(0.4)


def test_a_world_without_intruders_has_nothing_to_fly_ahead() -> None:
    with JSBSimWorld(_scenario(count=0)) as w:
        assert w.lookahead(PERIOD_TICKS, SAMPLE_TICKS) == 0
