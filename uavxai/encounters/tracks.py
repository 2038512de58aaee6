"""From model samples to trajectories in SI units (sample2track.m of MIT LL, in metres).

A track starts at the origin heading north at the sampled altitude and airspeed, and is
integrated as sample2track.m does, one explicit Euler step a second (or ``steps_per_second``
steps, the controls held over the second): the airspeed changes by the acceleration, the
heading by the turn rate, the height by the vertical rate, and the position moves with the
speed and heading at the start of the step. The local frame is the project's: x east, y north,
h up (m); heading clockwise from north.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uavxai.encounters.model import EncounterModel, InitialSample, Transitions
from uavxai.errors import UserError
from uavxai.geometry import clip, turn_rate_of_bank
from uavxai.units import FT, KT

FOOT_PER_MINUTE = FT / 60.0  # m/s
# UncorEncounterModel/getDynamicLimits: a fixed-wing track never slower than 30 ft/s.
MIN_FIXED_WING_SPEED = 30 * FT  # 9.144 m/s
LABELS = {"altitude": "L", "speed": "v", "acceleration": "\\dot v",
          "vertical_rate": "\\dot h", "turn_rate": "\\dot \\psi"}


@dataclass(frozen=True)
class Trajectory:
    """Samples of one aircraft: time (s), position (m, x east, y north, h up), velocity (m/s)."""

    t: np.ndarray
    x: np.ndarray
    y: np.ndarray
    h: np.ndarray
    vx: np.ndarray
    vy: np.ndarray
    vh: np.ndarray

    @property
    def speed(self) -> np.ndarray:
        """Horizontal speed (m/s)."""
        return np.hypot(self.vx, self.vy)

    @property
    def heading(self) -> np.ndarray:
        """Heading (rad, clockwise from north)."""
        return np.arctan2(self.vx, self.vy)


def sample2track(model: EncounterModel, initial: InitialSample, transitions: Transitions,
                 k: int = 0, steps_per_second: int = 1) -> Trajectory:
    """Track of sample ``k``: its initial altitude and airspeed, then its acceleration,
    vertical rate and turn rate second by second (kt, kt/s, ft/min, deg/s -> m, m/s)."""
    if not 1 <= steps_per_second <= 100:
        raise UserError("steps_per_second must be in 1..100")
    h0 = initial.values[k, model.index(LABELS["altitude"])] * FT
    v0 = initial.values[k, model.index(LABELS["speed"])] * KT
    col = {lab: transitions.labels.index(LABELS[lab])
           for lab in ("acceleration", "vertical_rate", "turn_rate")}
    controls = np.repeat(transitions.values[k], steps_per_second, axis=0)
    dv = controls[:, col["acceleration"]] * KT
    dh = controls[:, col["vertical_rate"]] * FOOT_PER_MINUTE
    dpsi = np.radians(controls[:, col["turn_rate"]])
    dt = 1.0 / steps_per_second

    def integral(rate: np.ndarray) -> np.ndarray:
        return np.concatenate(([0.0], np.cumsum(rate * dt)))

    speed = v0 + integral(dv)
    heading = integral(dpsi)
    vx, vy = speed * np.sin(heading), speed * np.cos(heading)
    return Trajectory(
        t=np.arange(len(speed)) * dt,
        x=integral(vx[:-1]), y=integral(vy[:-1]), h=h0 + integral(dh),
        vx=vx, vy=vy, vh=np.append(dh, dh[-1]),
    )


def is_flyable(model: EncounterModel, track: Trajectory,
               min_speed: float = MIN_FIXED_WING_SPEED) -> bool:
    """The MIT LL rejection tests: speed strictly inside the model's airspeed range and above
    ``min_speed`` (sample2track.m, getDynamicLimits: drops tracks that decelerate to near zero),
    no point below the ground (sample2track.m's CFIT test), and a vertical rate below the
    airspeed (UncorEncounterModel/sample)."""
    edges = model.boundaries[model.index(LABELS["speed"])] * KT
    speed = track.speed
    return bool(np.all(speed > max(edges[0], min_speed)) and np.all(speed < edges[-1])
                and np.all(track.h >= 0) and np.all(np.abs(track.vh) < speed))


def sample_track(model: EncounterModel, rng: np.random.Generator, seconds: int,
                 start: dict[str, int] | None = None, steps_per_second: int = 1,
                 min_speed: float = MIN_FIXED_WING_SPEED, max_tries: int = 1000) -> Trajectory:
    """One flyable track of ``seconds`` s from the model (rejection sampling, as MIT LL)."""
    if not 2 <= seconds <= 3600:
        raise UserError("a track lasts 2..3600 s")
    for _ in range(max_tries):
        initial = model.sample_initial(rng, 1, start)
        track = sample2track(model, initial, model.sample_transitions(rng, initial, seconds),
                             0, steps_per_second)
        if is_flyable(model, track, min_speed):
            return track
    raise UserError(f"{model.name}: no flyable track in {max_tries} draws "
                    f"(start={start}, min_speed={min_speed} m/s)")


def limit_track(track: Trajectory, max_speed: float = float("inf"),
                max_vertical_rate: float = float("inf"),
                max_bank: float = float("inf")) -> Trajectory:
    """``track`` within an aircraft's dynamic limits (as MIT LL's getDynamicLimits bounds a
    type's): horizontal speed at most ``max_speed``, vertical rate within
    +-``max_vertical_rate`` (m/s), turn rate within the coordinated turn of bank ``max_bank``
    (rad) at the speed flown, g tan(max_bank) / V; heading and positions integrated again as
    :func:`sample2track` does (the rates at the start of each step). Unchanged when nothing
    exceeds the limits."""
    dt = np.diff(track.t)
    speed = np.minimum(track.speed, max_speed)
    psi = np.unwrap(np.arctan2(track.vx, track.vy))
    rate = np.diff(psi) / dt
    top = turn_rate_of_bank(min(max_bank, 1.5), np.maximum(speed[:-1], 1e-6))
    over = (np.abs(track.vh) > max_vertical_rate).any() or (track.speed > max_speed).any()
    if not (over or (np.abs(rate) > top).any()):
        return track
    psi = psi[0] + np.concatenate(([0.0], np.cumsum(clip(rate, -top, top) * dt)))
    vx, vy = speed * np.sin(psi), speed * np.cos(psi)
    vh = clip(track.vh, -max_vertical_rate, max_vertical_rate)

    def integral(start: float, v: np.ndarray) -> np.ndarray:
        return start + np.concatenate(([0.0], np.cumsum(v[:-1] * dt)))

    return Trajectory(t=track.t, x=integral(track.x[0], vx), y=integral(track.y[0], vy),
                      h=integral(track.h[0], vh), vx=vx, vy=vy, vh=vh)
