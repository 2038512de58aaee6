"""The multi-aircraft world: the ownship and every intruder as separate JSBSim executives,
stepped in lockstep at the scenario's rate, with the intruders' pilots at about 1 Hz (or the
intruders flown ahead through a decision period while the ownship's command is searched for,
:meth:`JSBSimWorld.lookahead`: the same flight to the bit).

The inner loop is nothing but ``FGFDMExec.run()`` calls; states are read only when asked
for (the pipeline does so at about 10 Hz). A run that diverges is never an exception: the
world stops advancing and :meth:`JSBSimWorld.failure` says what happened.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable, Mapping

import jsbsim
import numpy as np

from uavxai.dynamics.aircraft import Aircraft, heading_from_deg
from uavxai.dynamics.behaviours import intruder_bank_limit_rad, make_pilots, newcomer_pilot
from uavxai.dynamics.environment import EnvironmentConfig
from uavxai.dynamics.flow import Entry
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.loiter import ScheduledWorld
from uavxai.dynamics.state import OWNSHIP_ID, TrafficState, intruder_id, member_id
from uavxai.dynamics.track_pilot import TrackLike
from uavxai.dynamics.traffic import draw_intruders
from uavxai.errors import UserError
from uavxai.scenario import IntruderSpec, Scenario, aircraft_speed_range
from uavxai.units import FT

log = logging.getLogger(__name__)

# The end of a run. The ground: below this height the aircraft is on or in the terrain (its
# wheels hang 0.22 m below the centre of gravity). The envelope: far outside anything the
# autopilot flies (bank limit 30 deg; airspeed half the aircraft's slowest autopilot speed to
# twice its fastest: 6-60 m/s for uav_fw, whose stall is 10 m/s), i.e. out of control.
GROUND_M = 1.0
ENVELOPE_AIRSPEED_FACTORS = (0.5, 2.0)  # times the aircraft's (speed-min, speed-max)
ENVELOPE_BANK_RAD = math.radians(80.0)
ENVELOPE_PITCH_RAD = math.radians(60.0)
SPEED_TOLERANCE_MPS = 1e-9  # float rounding of a speed computed from its components

# JSBSim's local velocities come as (east, north, down) feet/s
_NED_FT_TO_ENU_M = np.array([FT, FT, -FT])

_JSBSIM_STREAM = 0x4A5342  # spawn key of the JSBSim seeds, apart from the pilots' streams
MEMBER_SEED_INDEX = 1 << 30  # fleet member j's seed index: never an intruder's number


def jsbsim_seed(seed: int, index: int) -> int:
    """`simulation/randomseed` of aircraft ``index`` (0 = ownship) in a run seeded ``seed``."""
    state = np.random.SeedSequence(seed, spawn_key=(_JSBSIM_STREAM, index)).generate_state(1)
    return int(state[0] & 0x7FFFFFFF)


class JSBSimWorld(ScheduledWorld):
    """Ownship (row 0) and intruders (rows 1..N) flown by JSBSim.

    ``intruders`` None draws them from the scenario with ``seed`` (default: the scenario's
    seed), exactly as the kinematic model does. ``tracks`` (intruder index -> trajectory)
    flies those intruders along a track (:mod:`uavxai.dynamics.track_pilot`), from t = 0;
    start such an intruder on its track's first point and heading.
    """

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
        self.origin = scenario.world.origin
        self.frame = LocalFrame.from_origin(self.origin)
        if intruders is None:
            intruders = draw_intruders(scenario, np.random.default_rng(self.seed))
        self.intruders = list(intruders)
        # a fleet's members (docs/fleet.md) fly in rows after the intruders', so that every
        # intruder row, pilot, track and newcomer keeps its number
        self.members = scenario.member_starts()[1:]
        first = 1 + len(self.intruders)
        self._intruder_rows = range(1, first)
        self.member_rows = range(first, first + len(self.members))
        self.ids = (
            OWNSHIP_ID if not self.members else member_id(0),
            *(intruder_id(i + 1) for i in range(len(self.intruders))),
            *(member_id(j + 1) for j in range(len(self.members))),
        )
        self._pilots = make_pilots(scenario, self.intruders, self.seed, tracks)
        self._init_schedule(scenario, self.seed, len(self.intruders))
        self._cached: TrafficState | None = None
        self._failure: str | None = None
        self.lost_intruders: list[str] = []  # intruders that failed and were replaced, why
        self._checked: TrafficState | None = None  # the last state _check tested
        self._envelope_key: tuple[str, ...] | None = None  # the aircraft _envelope_cache is of
        self._envelope_cache = np.empty((2, 0))
        # Lookahead: how many ticks each row (ownship first, always 0) has flown ahead of the
        # ownship, the intruders' states at the kept ticks (tick -> one row per intruder), and
        # the JSBSim errors met ahead (row -> error: it ends the run when the ownship gets to
        # that tick, as it would have in lockstep).
        self._lead: list[int] = []
        self._kept: dict[int, np.ndarray] = {}
        self._ahead_errors: dict[int, jsbsim.BaseError] = {}

        self.aircraft: list[Aircraft] = []
        self._runs: list[Callable[[], bool]] = []
        try:
            self._build()
        except BaseException:
            self.close()
            raise
        self._runs = [a.run for a in self.aircraft]
        self._lead = [0] * len(self.aircraft)
        self._fly_pilots()

    def _build(self) -> None:
        sc = self.scenario
        avoid = sc.avoidance
        start = sc.ownship.start
        own = Aircraft(sc.ownship.aircraft, self.frame, self.dt, jsbsim_seed(self.seed, 0))
        self.aircraft.append(own)
        flyable = own.speed_range
        self._check_speed("ownship.start.speed_mps", start.speed_mps, sc.ownship.aircraft, flyable)
        limits = (max(flyable[0], avoid.speed_mps[0]), min(flyable[1], avoid.speed_mps[1]))
        if limits[0] >= limits[1]:
            raise UserError(
                f"avoidance.speed_mps = {list(avoid.speed_mps)}: aircraft "
                f"'{sc.ownship.aircraft}' flies between {flyable[0]:g} and {flyable[1]:g} m/s"
            )
        env = EnvironmentConfig.from_scenario(sc)
        if not env.calm:
            own.set_environment(env.wind_ne, env.turbulence, jsbsim_seed(self.seed, 0))
        own.set_limits(bank_limit_rad=math.radians(avoid.bank_limit_deg), speed_range=limits)
        self._own_speed_range = limits  # command_ownship's speed_max_mps stays within it
        own.start(start.x, start.y, start.h, heading_from_deg(start.heading_deg), start.speed_mps)
        for i, spec in enumerate(self.intruders, start=1):
            self.aircraft.append(self._intruder(i, spec, env))
        for j, s in enumerate(self.members, start=1):
            seed = jsbsim_seed(self.seed, MEMBER_SEED_INDEX + j)
            a = Aircraft(sc.ownship.aircraft, self.frame, self.dt, seed)
            self.aircraft.append(a)  # closed with the others if it fails to start
            if not env.calm:
                a.set_environment(env.wind_ne, env.turbulence, seed)
            a.set_limits(bank_limit_rad=math.radians(avoid.bank_limit_deg), speed_range=limits)
            a.start(s.x, s.y, s.h, heading_from_deg(s.heading_deg), s.speed_mps)

    def _intruder(self, i: int, spec: IntruderSpec, env: EnvironmentConfig) -> Aircraft:
        """The JSBSim aircraft of intruder row ``i`` (1-based), started and trimmed."""
        sc = self.scenario
        a = Aircraft(sc.intruders.aircraft, self.frame, self.dt, jsbsim_seed(self.seed, i))
        try:
            self._check_speed(
                f"intruder {i} speed_mps", spec.speed_mps, sc.intruders.aircraft, a.speed_range
            )
            a.set_limits(bank_limit_rad=intruder_bank_limit_rad(sc))
            if not env.calm:  # the same air for everyone; turbulence seeded per aircraft
                a.set_environment(env.wind_ne, env.turbulence, jsbsim_seed(self.seed, i))
            a.start(spec.x, spec.y, spec.h, heading_from_deg(spec.heading_deg), spec.speed_mps)
        except BaseException:
            a.close()
            raise
        return a

    @staticmethod
    def _check_speed(field: str, speed: float, aircraft: str, flyable: tuple[float, float]) -> None:
        """A UserError if ``speed`` is outside the aircraft's ``flyable`` range. A rounding's
        worth over is inside: a sampled track limited to the top speed has a speed of
        hypot(vx, vy), which may be 60.00000000000001 m/s against 60."""
        tol = SPEED_TOLERANCE_MPS
        if not flyable[0] - tol <= speed <= flyable[1] + tol:
            raise UserError(
                f"{field} = {speed:g} m/s: aircraft '{aircraft}' flies between "
                f"{flyable[0]:g} and {flyable[1]:g} m/s"
            )

    # ------------------------------------------------------------------------------ time
    @property
    def n(self) -> int:
        return len(self.aircraft)

    @property
    def trimmed(self) -> list[bool]:
        """Whether each aircraft's start trim converged (ownship first)."""
        return [a.trimmed for a in self.aircraft]

    def _integrate(self, ticks: int) -> bool:
        """Fly every aircraft ``ticks`` integration steps (those flown ahead only up to the
        ownship); False if JSBSim gave up.

        Each aircraft flies its whole chunk before the next one starts, not tick by tick in
        lockstep: the executives are independent (each with its own seeded generator; the
        intruders' pilots act only between chunks), so every aircraft flies the same bits,
        while one executive's working set stays in the CPU's caches through its chunk
        instead of 21 of them taking turns: lockstep cost 3-5x as much per
        ``FGFDMExec.run()`` here (benchmarks/performance/bench_run.py). A JSBSim error ends
        the run at the tick and row where lockstep would have met it first."""
        first: tuple[int, int, jsbsim.BaseError] | None = None  # (tick, row, error)
        lead = self._lead
        for row, run in enumerate(self._runs):
            if lead[row] >= ticks:
                lead[row] -= ticks
                continue
            begin, lead[row] = lead[row], 0  # the chunk's tick at which this row starts
            err = self._ahead_errors.pop(row, None)  # met ahead: at this row's first tick
            flown = 0 if err is not None else ticks - begin
            if err is None:
                flown, err = _fly(run, flown)
            if err is not None and (first is None or begin + flown < first[0]):
                first = (begin + flown, row, err)  # rows in order: lockstep's first on a tie
        if not any(lead):
            self._kept = {}
        if first is not None:
            self._failure = f"JSBSim stopped: {first[2]}"
            log.warning("%s at t = %.2f s", self._failure, self.t + first[0] * self.dt)
            return False
        return True

    def lookahead(self, ticks: int, every: int) -> int:
        """Fly the intruders up to ``ticks`` ahead of the ownship, keeping their states every
        ``every`` ticks; :meth:`step` then flies the ownship alone up to them. Returns the
        ticks flown ahead.

        Why: at a decision the ownship's next command is being searched for (on the
        companion's core), while nothing the intruders do until their pilots' next instant
        depends on the ownship, so they fly meanwhile and the search costs the world no time.
        The flight is the same to the bit as in lockstep (independent JSBSim executives, each
        with its own seeded generator), each intruder flying its whole stretch at once (see
        :meth:`_integrate`). The lookahead stops at the next pilot instant (its leavers are
        replaced clear of the ownship). An intruder that leaves its envelope ahead is
        replaced where the ownship meets it, as in lockstep: its newcomer flies from there
        with the ownship, and what the wreck flew beyond is dropped with it. States may then
        be read only at the kept ticks: multiples of ``every`` and of the loiter law's
        period."""
        rows = self._intruder_rows  # a member's flight depends on its commands: never ahead
        if any(self._lead) or self._halted() or not rows or ticks < 1:
            return 0
        start = self._steps
        ticks = min(int(ticks), self._pilot_period - start % self._pilot_period)
        keep = math.gcd(int(every), self._guidance_period)
        marks = [k for k in range(1, ticks + 1) if (start + k) % keep == 0 or k == ticks]
        self._kept = {start: _read(self.aircraft[1:])}
        self._kept.update((start + k, np.full_like(self._kept[start], np.nan)) for k in marks)
        for row in rows:
            self._lead[row] = self._fly_ahead(row, start, marks)
        return self.ahead_ticks

    def _fly_ahead(self, row: int, start: int, marks: list[int]) -> int:
        """Fly ``row`` to the last of ``marks`` (ticks after ``start``), keeping its state
        at each; the ticks it flew (fewer if JSBSim gave up: the error waits for the
        ownship)."""
        run, get, kept = self._runs[row], self.aircraft[row].raw_state, self._kept
        done = 0
        for mark in marks:
            flown, err = _fly(run, mark - done)
            done += flown
            if err is not None:
                self._ahead_errors[row] = err
                return done
            kept[start + mark][row - 1] = get()
        return done

    @property
    def ahead_ticks(self) -> int:
        """How many ticks the intruders fly ahead of the ownship now (:meth:`lookahead`),
        all of them (the least any row is ahead)."""
        return min((self._lead[r] for r in self._intruder_rows), default=0)

    def _halted(self) -> bool:
        return self._failure is not None

    def _stopped(self, state: TrafficState) -> bool:
        # The pilots see the state every second; the same read tells whether anyone diverged.
        return self._check(state)

    def _command_intruder(
        self, row: int, bank: float, speed: float, alt: float | None = None
    ) -> None:
        self.aircraft[row].command(bank_cmd_rad=bank, speed_target_mps=speed, alt_target_m=alt)

    def _replace(self, entries: list[Entry]) -> None:
        """Intruders that left the area make way for newcomers entering at the edge."""
        env = EnvironmentConfig.from_scenario(self.scenario)
        ids = list(self.ids)
        for e in entries:
            row = e.replaces + 1
            spec = e.to_spec(self.scenario.intruders.behaviour)
            self.aircraft[row].close()
            self.aircraft[row] = self._intruder(e.number, spec, env)
            self._pilots[row - 1] = newcomer_pilot(self.scenario, spec, self.seed, e.number)
            ids[row] = e.id
            # A newcomer flies from here with the ownship; what its predecessor flew ahead
            # (and any error it met there) goes with it.
            self._lead[row] = 0
            self._ahead_errors.pop(row, None)
        self.ids = tuple(ids)
        self._runs = [a.run for a in self.aircraft]
        self._cached = None

    # ----------------------------------------------------------------------------- state
    def state(self) -> TrafficState:
        """All aircraft now, SI, local ENU (see :class:`TrafficState`)."""
        if self._cached is None:
            if any(self._lead):  # those ahead as they were at this tick, the others now
                kept = self._kept.get(self._steps)
                if kept is None:
                    raise RuntimeError(
                        f"state at tick {self._steps} asked for while the intruders fly "
                        f"ahead: only the kept ticks {sorted(self._kept)} can be read"
                    )
                raw = np.empty((self.n, kept.shape[1]))
                raw[1:] = kept
                for row, lead in enumerate(self._lead):
                    if not lead:
                        raw[row] = self.aircraft[row].raw_state()
            else:
                raw = _read(self.aircraft)
            pos = np.empty((len(raw), 3))
            pos[:, 0], pos[:, 1], _ = self.frame.to_local(raw[:, 0], raw[:, 1], 0.0)
            pos[:, 2] = raw[:, 2] * FT
            self._cached = TrafficState(
                t=self.t,
                ids=self.ids,
                pos=pos,
                vel=raw[:, 3:6] * _NED_FT_TO_ENU_M,
                att=raw[:, 6:9].copy(),
                airspeed=raw[:, 9] * FT,
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
        """Write the ownship's autopilot inputs; None leaves one unchanged. The bank command
        is limited to the scenario's bank limit and the speed target to its speed range
        by the autopilot itself; ``alt_target_m`` is a height above ground (local h);
        ``speed_max_mps`` lowers (or restores) the top of the speed range, within it: an
        operator's airspeed, which avoidance may fly below but never above."""
        self.command_row(0, bank_cmd_rad, accel_cmd_mps2, speed_target_mps, alt_target_m,
                         speed_max_mps)  # fmt: skip

    def command_row(
        self,
        row: int,
        bank_cmd_rad: float | None = None,
        accel_cmd_mps2: float | None = None,
        speed_target_mps: float | None = None,
        alt_target_m: float | None = None,
        speed_max_mps: float | None = None,
    ) -> None:
        """:meth:`command_ownship` of fleet row ``row`` (0: the ownship; else a member's)."""
        given = {
            "bank_cmd_rad": bank_cmd_rad,
            "accel_cmd_mps2": accel_cmd_mps2,
            "speed_target_mps": speed_target_mps,
            "alt_target_m": alt_target_m,
            "speed_max_mps": speed_max_mps,
        }
        self._finite_commands(**given)
        if speed_max_mps is not None:
            lo, hi = self._own_speed_range
            given["speed_max_mps"] = min(max(float(speed_max_mps), lo), hi)
        if bank_cmd_rad is not None and row == 0:
            self._orbit = None  # a bank command takes the aircraft off its loiter orbit
        elif bank_cmd_rad is not None:
            self._member_orbits = {r: o for r, o in self._member_orbits.items() if r != row}
        self.aircraft[row].command(**given)

    def _bank_from_guidance(self, bank_rad: float, row: int = 0) -> None:
        self.aircraft[row].command(bank_cmd_rad=bank_rad)

    def ownship_command(self) -> dict[str, float]:
        """The ownship's current bank command, acceleration command, speed and height targets
        (the speed target moves while an acceleration is commanded)."""
        return self.aircraft[0].read_command()

    def powered_ownship(self) -> Aircraft:
        """The ownship's JSBSim model: it reports the electrical power its motor takes."""
        return self.aircraft[0]

    # --------------------------------------------------------------------------- failure
    def failure(self) -> str | None:
        """Why the run cannot go on (NaN, ground, out of the flight envelope), or None."""
        if self._failure is None:
            self._check(self.state())
        return self._failure

    def _check(self, s: TrafficState) -> bool:
        """Latch the first failure found in ``s``; True if the run has failed.

        An intruder that fails (stalls into the ground, leaves its envelope) is lost, not the
        end of the run, when traffic persists: a newcomer enters at the edge in its place at
        once, as for one that flew out of the area (``lost_intruders`` says who and why). The
        ownship's failure, or any without persistent traffic, ends the run."""
        if self._failure is not None or s is self._checked:
            return self._failure is not None
        self._checked = s  # step() and failure() both ask of the same sample: test it once
        envelope = self._envelope()
        if _all_healthy(s, envelope):
            return False
        lost = []
        for i, who in enumerate(s.ids):
            reason = _diagnose(who, s.pos[i], s.att[i], s.airspeed[i], envelope[:, i])
            if reason and i in self._intruder_rows and self._flow is not None:
                lost.append(i - 1)
                self.lost_intruders.append(f"{reason} at t = {s.t:.2f} s")
                log.info("intruder lost: %s; a newcomer enters instead", reason)
            elif reason:
                self._failure = f"{reason} at t = {s.t:.2f} s"
                log.info("run ends: %s", self._failure)
                return True
        if lost:
            keep_clear = s.pos[self.fleet_rows]
            self._replace(self._flow.enter(lost, keep_clear, min_distance_m=self._clearance))
        return False

    def _envelope(self) -> np.ndarray:
        """Airspeed bounds of each row's envelope (2 x n, m/s), from its aircraft's speed
        range as its package declares it (:data:`ENVELOPE_AIRSPEED_FACTORS`, not narrowed by
        avoidance.speed_mps): the intruders may fly another aircraft than the ownship."""
        key = tuple(a.name for a in self.aircraft)
        if self._envelope_key != key:
            ranges = np.array([aircraft_speed_range(a.name) for a in self.aircraft]).T
            self._envelope_cache = ranges * np.array(ENVELOPE_AIRSPEED_FACTORS)[:, None]
            self._envelope_key = key
        return self._envelope_cache

    def step(self, n: int = 1) -> None:
        super().step(n)
        if self._flow is not None:  # the state handed out next has no lost intruder in it
            self._check(self.state())

    def close(self) -> None:
        for a in self.aircraft:
            a.close()
        self.aircraft = []
        self._runs = []
        self._lead = []

    def __enter__(self) -> JSBSimWorld:
        return self

    def __exit__(self, *exc: object) -> None:
        self.close()


def _fly(run: Callable[[], bool], ticks: int) -> tuple[int, jsbsim.BaseError | None]:
    """``run`` (one executive's ``FGFDMExec.run``) ``ticks`` times: the ticks flown, and the
    JSBSim error that stopped it (JSBSim gives up on a diverged state) or None."""
    for done in range(ticks):
        try:
            run()
        except jsbsim.BaseError as exc:
            return done, exc
    return ticks, None


def _read(aircraft: list[Aircraft]) -> np.ndarray:
    """The raw states (STATE_PROPERTIES, JSBSim units) of ``aircraft``, one row each."""
    return np.array([a.raw_state() for a in aircraft])


def _all_healthy(s: TrafficState, envelope: np.ndarray) -> bool:
    """Every aircraft inside the envelope (airspeed bounds, 2 x n), in one vectorised test
    (the common case: then nobody needs :func:`_diagnose`)."""
    return _within_envelope(s.pos, s.att, s.airspeed, envelope)


def _within_envelope(
    pos: np.ndarray, att: np.ndarray, airspeed: np.ndarray, envelope: np.ndarray
) -> bool:
    lo, hi = envelope
    with np.errstate(invalid="ignore"):  # NaN compares False, which is what we want
        inside = (
            (pos[:, 2] >= GROUND_M)
            & (airspeed >= lo)
            & (airspeed <= hi)
            & (np.abs(att[:, 0]) <= ENVELOPE_BANK_RAD)
            & (np.abs(att[:, 1]) <= ENVELOPE_PITCH_RAD)
        )
    return bool(inside.all() and np.isfinite(pos).all())  # two reductions, not five: per sample


def _diagnose(
    who: str, pos: np.ndarray, att: np.ndarray, airspeed: float, envelope: np.ndarray
) -> str | None:
    """What is wrong with one aircraft's state, in words, or None."""
    if not (np.all(np.isfinite(pos)) and np.all(np.isfinite(att)) and math.isfinite(airspeed)):
        return f"NaN in {who} state"
    if pos[2] < GROUND_M:
        return f"{who} hit the ground"
    lo, hi = envelope
    if not lo <= airspeed <= hi:
        return f"{who} left the flight envelope (airspeed {airspeed:.1f} m/s)"
    if abs(att[0]) > ENVELOPE_BANK_RAD:
        return f"{who} left the flight envelope (bank {math.degrees(att[0]):.0f} deg)"
    if abs(att[1]) > ENVELOPE_PITCH_RAD:
        return f"{who} left the flight envelope (pitch {math.degrees(att[1]):.0f} deg)"
    return None
