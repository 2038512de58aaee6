"""Standard manoeuvres of the autopilot on the real JSBSim model: fly one, record every
integration step, measure it. The tests assert on these measures,
``docs/dynamics/plot_step_responses.py`` draws the same runs and the climb and gust studies
(``benchmarks/studies/``) fly them over many seeds.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from uavxai.avoidance.types import PlannerConfig
from uavxai.dynamics.aircraft import Aircraft
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.world import JSBSimWorld
from uavxai.scenario import Scenario, default_scenario
from uavxai.units import G


@dataclass
class Record:
    """Ownship time series at every integration step; the command changes at t = 0."""

    t: np.ndarray
    bank: np.ndarray  # rad
    bank_rate: np.ndarray  # rad/s, finite difference of bank
    heading: np.ndarray  # rad, unwrapped
    h: np.ndarray  # m
    airspeed: np.ndarray  # m/s
    speed_target: np.ndarray  # m/s
    command: dict[str, float] = field(default_factory=dict)
    failure: str | None = None


def flight_test_scenario(speed_mps: float = 20.0, h: float = 150.0, seed: int = 0) -> Scenario:
    """The ownship alone, in the middle of the default world, heading north."""
    return default_scenario(
        "flight-test",
        seed=seed,
        intruders={"count": 0},
        ownship={"start": {"x": 1000, "y": 1000, "h": h, "heading_deg": 0, "speed_mps": speed_mps}},
    )


def fly(
    scenario: Scenario,
    duration_s: float,
    lead_s: float = 1.0,
    schedule: Callable[[float], dict[str, float]] | None = None,
    **command: float,
) -> Record:
    """Fly ``lead_s`` undisturbed, then give ``command`` (keywords of
    ``JSBSimWorld.command_ownship``) and fly ``duration_s`` more. ``schedule(t)`` may return
    further commands at each step after that. Time in the record is relative to the command."""
    world = JSBSimWorld(scenario)
    try:
        world.advance(lead_s)
        world.command_ownship(**command)
        n = round(duration_s / world.dt) + 1
        rows = np.empty((n, 6))
        t0 = world.t
        for k in range(n):
            if k:
                if schedule is not None:
                    world.command_ownship(**schedule(world.t - t0))
                world.step()
            s = world.state()
            rows[k] = (s.t - t0, s.att[0, 0], s.att[0, 2], s.pos[0, 2], s.airspeed[0], 0.0)
            rows[k, 5] = world.ownship_command()["speed_target_mps"]
        failure = world.failure()
    finally:
        world.close()
    t = rows[:, 0]
    return Record(
        t=t,
        bank=rows[:, 1],
        bank_rate=np.gradient(rows[:, 1], t),
        heading=np.unwrap(rows[:, 2]),
        h=rows[:, 3],
        airspeed=rows[:, 4],
        speed_target=rows[:, 5],
        command=dict(command),
        failure=failure,
    )


CLIMB_TIMES = (1.0, 2.0, 4.0, 8.0)  # s after the vertical command


def climb_scenario(speed: float, turbulence: str, seed: int) -> Scenario:
    """The ownship alone with the vertical action set, at ``speed``, in ``turbulence``."""
    start = {"x": 1000, "y": 1000, "h": 150, "heading_deg": 0, "speed_mps": speed}
    return default_scenario(
        "climb-probe",
        seed=seed,
        intruders={"count": 0},
        ownship={"start": start},
        environment={"turbulence": turbulence},
        avoidance={"actions": "vertical"},
    )


def height_gained(scenario: Scenario, bank_deg: float, vertical: int) -> list[float]:
    """Height change at CLIMB_TIMES after the vertical command ``vertical`` (+1 climb, -1
    descend), from level flight or a held bank of ``bank_deg``, at the start's speed target."""
    cfg = PlannerConfig.from_scenario(scenario)
    world = JSBSimWorld(scenario)
    try:
        speed = scenario.ownship.start.speed_mps
        world.command_ownship(bank_cmd_rad=math.radians(bank_deg), speed_target_mps=speed)
        world.advance(6.0)
        h0 = world.state().pos[0, 2]
        world.command_ownship(alt_target_m=cfg.height_target(vertical, h0))
        out, t = [], 0.0
        for t_next in CLIMB_TIMES:
            world.advance(t_next - t)
            t = t_next
            out.append(float(world.state().pos[0, 2] - h0))
    finally:
        world.close()
    return out


# A lone Aircraft (no world, no pilots) in wind and turbulence, for the weather's own effect.
FRAME = LocalFrame(34.1230, 108.8370, 400.0)  # any place: the weather is the same everywhere
DT = 1.0 / 120.0


def flown(
    heading_deg: float,
    wind: tuple[float, float],
    turbulence: str = "none",
    seed: int = 1,
    seconds: float = 60.0,
    speed: float = 20.0,
    banks: list[tuple[float, float]] | None = None,
) -> np.ndarray:
    """Rows of raw_state() at 10 Hz (lat, lon, h ft, v east/north/down fps, phi, theta, psi,
    vt fps) of an aircraft started level in this weather; ``banks`` [(t, bank_rad)]."""
    a = Aircraft("uav_fw", FRAME, DT, seed=7)
    a.set_environment(wind, turbulence, seed)
    if not a.start(1000.0, 1000.0, 120.0, math.radians(heading_deg), speed):
        raise RuntimeError(f"uav_fw did not trim at {speed} m/s in {turbulence} turbulence")
    banks = sorted(banks or [])
    rows = []
    for k in range(round(seconds / DT)):
        t = k * DT
        while banks and banks[0][0] <= t:
            a.command(bank_cmd_rad=banks.pop(0)[1])
        a.run()
        if k % 12 == 11:
            rows.append(a.raw_state())
    a.close()
    return np.array(rows)


# ------------------------------------------------------------------------------ measures
def bank_step_measures(rec: Record, bank_cmd_rad: float) -> dict[str, float]:
    """Rise time to 90 % and to 95 % of the command, overshoot (fraction of the command),
    peak roll rate, final bank."""
    frac = rec.bank / bank_cmd_rad
    return {
        "rise_90_s": first_time(rec.t, frac >= 0.9),
        "rise_95_s": first_time(rec.t, frac >= 0.95),
        "overshoot": max(0.0, float(frac.max()) - 1.0),
        "peak_roll_rate_rad_s": float(np.abs(rec.bank_rate).max()),
        "final_bank_rad": float(rec.bank[-1]),
    }


def reversal_measures(rec: Record, start_s: float) -> dict[str, float]:
    """For a bank reversal commanded at ``start_s``: the mean roll rate over the middle
    80 % of the roll, and the peak roll rate after the command."""
    after = rec.t >= start_s
    b0, b1 = rec.bank[after][0], rec.bank[-1]
    lo, hi = b0 + 0.1 * (b1 - b0), b0 + 0.9 * (b1 - b0)
    sign = math.copysign(1.0, b1 - b0)
    t_lo = first_time(rec.t, after & (sign * rec.bank >= sign * lo))
    t_hi = first_time(rec.t, after & (sign * rec.bank >= sign * hi))
    return {
        "mean_roll_rate_rad_s": abs(hi - lo) / (t_hi - t_lo),
        "peak_roll_rate_rad_s": float(np.abs(rec.bank_rate[after]).max()),
    }


def turn_measures(rec: Record, window_s: float = 20.0) -> dict[str, float]:
    """Over the last ``window_s``: the turn rate flown, the coordinated-turn rate
    g tan(phi) / V for the bank and airspeed flown, their relative error; and over the whole
    run the largest height deviation from the start."""
    last = rec.t >= rec.t[-1] - window_s
    t = rec.t[last]
    rate = float(np.polyfit(t, rec.heading[last], 1)[0])
    expected = G * math.tan(float(rec.bank[last].mean())) / float(rec.airspeed[last].mean())
    return {
        "turn_rate_rad_s": rate,
        "expected_rad_s": expected,
        "turn_rate_error": rate / expected - 1.0,
        "height_error_m": float(np.abs(rec.h - rec.h[0]).max()),
    }


def speed_measures(rec: Record) -> dict[str, float]:
    """Largest |airspeed - speed target|, and the speed change achieved."""
    return {
        "speed_error_mps": float(np.abs(rec.airspeed - rec.speed_target).max()),
        "speed_change_mps": float(rec.airspeed[-1] - rec.airspeed[0]),
    }


def heading_measures(rec: Record) -> dict[str, float]:
    return {"heading_drift_rad": float(np.abs(rec.heading - rec.heading[0]).max())}


def climb_measures(rec: Record, target_m: float) -> dict[str, float]:
    """Peak climb (or sink) rate, final height error."""
    rate = np.gradient(rec.h, rec.t)
    return {
        "peak_climb_rate_mps": float(rate.max()),
        "peak_sink_rate_mps": float(-rate.min()),
        "final_height_error_m": float(rec.h[-1] - target_m),
    }


def first_time(t: np.ndarray, reached: np.ndarray) -> float:
    """The first time at which ``reached`` holds (inf if never)."""
    idx = np.flatnonzero(reached)
    return float(t[idx[0]]) if idx.size else math.inf
