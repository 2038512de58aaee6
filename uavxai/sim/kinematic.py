"""The kinematic world: the encounter model flying the same aircraft the JSBSim world flies,
behind the same interface, so that one episode engine runs both.

The ownship follows its autopilot commands the way the planners predict it (bank command
reached at the roll-rate limit, coordinated turn, along-track acceleration within the speed
limits, climb towards the height target at a bounded rate: :class:`EncounterModel`);
intruders are flown by the same pilots as in the JSBSim world (:func:`make_pilots`), at the
speed their pilot sets, and at their height unless the pilot gives a height target (the
`track` pilot): then their climb rate is their autopilot's, gain x (target - height) clipped
to +-its climb-rate limit (:func:`uavxai.scenario.aircraft_height_loop`; 0.2 /s and 2.5 m/s
for ga_c172), integrated exactly over each step (:func:`height_step`). A steady wind
(``environment.wind``) carries everyone over the ground; turbulence is JSBSim-only (the model
has no gust response). It never fails: :meth:`failure` is always None.

Commands are taken as the JSBSim world takes them (``command_ownship``); a speed target is
flown as the largest allowed acceleration towards it.
"""

from __future__ import annotations

import dataclasses
import math
from collections.abc import Mapping

import numpy as np

from uavxai.avoidance.model import PHI, PHI_CMD, PSI, STATE_DIM, EncounterModel, V
from uavxai.avoidance.types import PlannerConfig
from uavxai.dynamics.behaviours import make_pilots, newcomer_pilot
from uavxai.dynamics.environment import EnvironmentConfig
from uavxai.dynamics.flow import Entry
from uavxai.dynamics.loiter import ScheduledWorld
from uavxai.dynamics.state import OWNSHIP_ID, TrafficState, intruder_id
from uavxai.dynamics.track_pilot import TrackLike
from uavxai.dynamics.traffic import draw_intruders
from uavxai.geometry import clip
from uavxai.scenario import IntruderSpec, Scenario, aircraft_height_loop
from uavxai.vocabulary import HOLD

_FAR = 1e12  # a goal nobody reaches: the model's goal only sets the height target here


class KinematicWorld(ScheduledWorld):
    """Ownship (row 0) and intruders (rows 1..N) on the encounter model; the interface of
    :class:`uavxai.dynamics.world.JSBSimWorld`."""

    def __init__(
        self,
        scenario: Scenario,
        intruders: list[IntruderSpec] | None = None,
        seed: int | None = None,
        tracks: Mapping[int, TrackLike] | None = None,
    ) -> None:
        self.scenario = scenario
        self.seed = scenario.seed if seed is None else int(seed)
        self.dt = 1.0 / scenario.dynamics.rate_hz
        if intruders is None:
            intruders = draw_intruders(scenario, np.random.default_rng(self.seed))
        self.intruders = list(intruders)
        self.ids = (OWNSHIP_ID, *(intruder_id(i + 1) for i in range(len(self.intruders))))
        self.config = PlannerConfig.from_scenario(scenario)
        self._models: dict[float, EncounterModel] = {}
        start = scenario.ownship.start
        self._own = np.array(
            [start.x, start.y, start.h, start.speed_mps, math.radians(start.heading_deg), 0, 0, 0],
            dtype=float,
        )
        self._traffic = np.array(
            [[s.x, s.y, s.h, s.speed_mps, math.radians(s.heading_deg), 0, 0, 0] for s in intruders],
            dtype=float,
        ).reshape(len(self.intruders), STATE_DIM)
        self._vh = 0.0
        # The intruders' height targets (nan: hold the height) and climb rates.
        self._intruder_alt = np.full(len(self.intruders), np.nan)
        self._intruder_vh = np.zeros(len(self.intruders))
        self._height_loop = aircraft_height_loop(scenario.intruders.aircraft)
        # Ground velocity = air velocity + wind (the model's paths drift with it already);
        # turbulence is JSBSim-only.
        self._wind = np.asarray(EnvironmentConfig.from_scenario(scenario).wind_enu, dtype=float)
        self._accel = 0.0
        self._speed_target: float | None = None
        self._speed_max = float(self.config.speed_mps[1])  # the autopilot's ceiling
        self._alt_target = float(start.h)
        self._pilots = make_pilots(scenario, self.intruders, self.seed, tracks)
        self._init_schedule(scenario, self.seed, len(self.intruders))
        self._cached: TrafficState | None = None
        self._fly_pilots()

    # ------------------------------------------------------------------------------ time
    @property
    def n(self) -> int:
        return len(self.ids)

    def _integrate(self, ticks: int) -> bool:
        self._fly(ticks * self.dt)
        return True

    def _halted(self) -> bool:
        return False  # the kinematic model never diverges

    def _stopped(self, state: TrafficState) -> bool:
        return False

    def _model(self, accel: float) -> EncounterModel:
        key = abs(float(accel))
        model = self._models.get(key)
        if model is None:
            model = self._models[key] = EncounterModel(
                dataclasses.replace(self.config, accel_mps2=key)
            )
        model.hold_speed_band((self.config.speed_mps[0], self._speed_max))
        return model

    def _fly(self, duration: float) -> None:
        accel = self._accel
        target = self._speed_target
        if target is None and self._own[V] > self._speed_max:
            target = self._speed_max  # a lowered ceiling: the autopilot's target drops to it
        if target is not None:
            gap = target - self._own[V]
            accel = math.copysign(min(abs(gap) / duration, self.config.accel_mps2), gap)
        model = self._model(accel)
        # The bank command is written straight into the state; "hold bank" then flies it.
        action = HOLD + (0 if accel == 0 else (-1 if accel > 0 else 1))
        h0 = float(self._own[2])
        goal = np.array([_FAR, _FAR, self._alt_target])
        # the model flies in the wind (config.wind_mps)
        self._own = model.fly_end(self._own[None], np.array([action]), goal, duration)[0]
        self._vh = (float(self._own[2]) - h0) / duration
        if len(self._traffic):
            _, self._traffic = model.fly_commanded(
                self._traffic, self._traffic[:, PHI_CMD], duration, samples=False
            )
            climbing = np.isfinite(self._intruder_alt)
            if climbing.any():
                gain, limit = self._height_loop
                h0 = self._traffic[climbing, 2]
                h1 = height_step(h0, self._intruder_alt[climbing], gain, limit, duration)
                self._traffic[climbing, 2] = h1
                self._intruder_vh[climbing] = (h1 - h0) / duration

    def _command_intruder(
        self, row: int, bank: float, speed: float, alt: float | None = None
    ) -> None:
        self._traffic[row - 1, PHI_CMD] = bank
        self._traffic[row - 1, V] = speed  # the pilot's speed target, held
        self._intruder_alt[row - 1] = np.nan if alt is None else float(alt)
        if alt is None:
            self._intruder_vh[row - 1] = 0.0

    def _replace(self, entries: list[Entry]) -> None:
        """As the JSBSim world: a newcomer at the edge for every intruder that left."""
        ids = list(self.ids)
        for e in entries:
            spec = e.to_spec(self.scenario.intruders.behaviour)
            self._traffic[e.replaces] = (e.x, e.y, e.h, e.speed_mps, e.heading_rad, 0, 0, 0)
            self._pilots[e.replaces] = newcomer_pilot(self.scenario, spec, self.seed, e.number)
            self._intruder_alt[e.replaces] = np.nan
            self._intruder_vh[e.replaces] = 0.0
            ids[e.replaces + 1] = e.id
        self.ids = tuple(ids)
        self._cached = None

    # ----------------------------------------------------------------------------- state
    def state(self) -> TrafficState:
        if self._cached is None:
            rows = np.vstack([self._own[None], self._traffic])
            v, psi = rows[:, V], rows[:, PSI]
            vel = np.stack([v * np.sin(psi), v * np.cos(psi), np.zeros_like(v)], axis=1)
            vel += self._wind  # over the ground
            vel[0, 2] = self._vh
            vel[1:, 2] = self._intruder_vh
            att = np.stack([rows[:, PHI], np.zeros_like(v), np.mod(psi, 2 * math.pi)], axis=1)
            self._cached = TrafficState(
                t=self.t, ids=self.ids, pos=rows[:, :3].copy(), vel=vel, att=att, airspeed=v.copy()
            )
        return self._cached

    # -------------------------------------------------------------------------- commands
    def command_ownship(
        self,
        bank_cmd_rad: float | None = None,
        accel_cmd_mps2: float | None = None,
        speed_target_mps: float | None = None,
        alt_target_m: float | None = None,
        speed_max_mps: float | None = None,
    ) -> None:
        """As the JSBSim world: the bank command is clamped to the bank limit, the speed
        target to the speed range (whose top ``speed_max_mps`` lowers); an acceleration
        command cancels a speed target."""
        self._finite_commands(
            bank_cmd_rad=bank_cmd_rad,
            accel_cmd_mps2=accel_cmd_mps2,
            speed_target_mps=speed_target_mps,
            alt_target_m=alt_target_m,
            speed_max_mps=speed_max_mps,
        )
        if speed_max_mps is not None:
            lo, hi = self.config.speed_mps
            self._speed_max = min(max(float(speed_max_mps), lo), hi)
        if bank_cmd_rad is not None:
            self._orbit = None  # a bank command takes the aircraft off its loiter orbit
            self._bank_from_guidance(bank_cmd_rad)
        if accel_cmd_mps2 is not None:
            self._accel = float(accel_cmd_mps2)
            self._speed_target = None
        if speed_target_mps is not None:
            lo = self.config.speed_mps[0]
            self._speed_target = min(max(float(speed_target_mps), lo), self._speed_max)
            self._accel = 0.0
        if alt_target_m is not None:
            self._alt_target = float(alt_target_m)
        self._cached = None

    def _bank_from_guidance(self, bank_rad: float, row: int = 0) -> None:
        lim = self.config.bank_limit_rad
        self._own[PHI_CMD] = min(max(float(bank_rad), -lim), lim)
        self._cached = None

    def ownship_command(self) -> dict[str, float]:
        return {
            "bank_cmd_rad": float(self._own[PHI_CMD]),
            "accel_cmd_mps2": self._accel,
            "speed_target_mps": float(
                self._own[V] if self._speed_target is None else self._speed_target
            ),
            "alt_target_m": self._alt_target,
        }

    def powered_ownship(self) -> None:
        """A point mass has no motor: no power, no battery."""
        return None

    # --------------------------------------------------------------------------- failure
    def failure(self) -> str | None:
        return None

    @property
    def lost_intruders(self) -> list[str]:
        return []  # the closed-form model's intruders cannot fail

    def close(self) -> None:
        self._pilots = []

    def __enter__(self) -> KinematicWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def height_step(h0, target, gain: float, limit: float, duration: float) -> np.ndarray:
    """Heights after ``duration`` s of dh/dt = clip(gain (target - h), -limit, limit), exactly:
    at the limit while the gap exceeds limit / gain, then first-order (time constant 1 / gain)
    towards the target. Arrays ``h0``, ``target`` of the same shape; ``gain`` > 0."""
    h0, target = np.asarray(h0, dtype=float), np.asarray(target, dtype=float)
    gap = target - h0
    knee = limit / gain  # below this gap the climb rate is proportional
    t_lim = clip((np.abs(gap) - knee) / limit, 0.0, duration)  # time spent at the limit
    gap_after = gap - np.sign(gap) * limit * t_lim
    return target - gap_after * np.exp(-gain * (duration - t_lim))
