"""Simulated ADS-B: what a UAV's receiver hears of the cooperative traffic around it.

Per intruder, one report every ``1 / rate_hz`` seconds (each intruder on its own phase, as
real transponders are not synchronised), with

* a position error drawn from the NACp category: NACp bounds the 95 % horizontal radius of
  the error (EPU), so for a circular Gaussian with per-axis sigma s, P(r <= R) =
  1 - exp(-R^2 / (2 s^2)) = 0.95 gives s = R / sqrt(-2 ln 0.05) = R / 2.448; the vertical
  error uses the VEPU of DO-260B (95 %, one axis: s = V / 1.960);
* a velocity error drawn from the NACv category the same way (horizontal 95 % radius, and
  its vertical bound);
* a latency: the report describes the state ``latency_s`` before it is delivered;
* a loss probability ``dropout`` per report.

A ``noncooperative`` share of the intruders sends nothing; they are seen only by the onboard
sensor (:mod:`uavxai.surveillance.sensor`) or, without one, not at all. Which intruders are
non-cooperative depends only on the seed and the intruder's number, so it does not change
when other intruders come and go. Errors are white (independent from report to report).

``model: truth`` delivers every intruder's exact state at every call, with no latency.

Everything is seeded: the same seed and the same sequence of states give the same reports.
The functions at the end turn a report into the field values of a MAVLink ADSB_VEHICLE
message and back, so the reports can travel through the bridge as a real receiver's would.
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, field, fields

import numpy as np

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState, is_member, member_id
from uavxai.errors import UserError
from uavxai.scenario import Scenario, checked
from uavxai.scenario import Surveillance as SurveillanceSection
from uavxai.surveillance.emitters import TrafficCategories, emitter_category, emitter_type
from uavxai.surveillance.sensor import SensorConfig, sensor_sees

# 95 % horizontal position bound (EPU) per NACp, m (DO-260B Table 2-14). 8 = 0.05 NM.
NACP_EPU_M: dict[int, float] = {
    5: 926.0,
    6: 555.6,
    7: 185.2,
    8: 92.6,
    9: 30.0,
    10: 10.0,
    11: 3.0,
}
# 95 % vertical position bound (VEPU), m: defined for NACp 9-11 only; below that the
# geometric altitude bound is taken as NACp 9's.
NACP_VEPU_M: dict[int, float] = {5: 45.0, 6: 45.0, 7: 45.0, 8: 45.0, 9: 45.0, 10: 15.0, 11: 4.0}
# 95 % horizontal velocity bound per NACv, m/s, and the vertical (geometric rate) bound,
# 50 / 15 / 5 / 1.5 ft/s.
NACV_HFOM_MPS: dict[int, float] = {1: 10.0, 2: 3.0, 3: 1.0, 4: 0.3}
NACV_VFOM_MPS: dict[int, float] = {1: 15.24, 2: 4.572, 3: 1.524, 4: 0.4572}

# 95 % radius of a circular 2-D Gaussian / its per-axis sigma, and the 1-D 95 % factor.
R95_PER_SIGMA_2D = math.sqrt(-2.0 * math.log(0.05))  # 2.4477
R95_PER_SIGMA_1D = 1.959963984540054

# spawn keys of the random streams, apart from every other stream of a run
_NOISE_STREAM = 0x414453  # "ADS"
_COOP_STREAM = 0x434F4F  # "COO"


def sigma_from_r95(r95: float) -> float:
    """Per-axis sigma of a circular 2-D Gaussian whose 95 % radius is ``r95``."""
    return r95 / R95_PER_SIGMA_2D


def nacp_sigmas(nacp: int) -> tuple[float, float]:
    """(horizontal per-axis, vertical) 1-sigma position error of NACp ``nacp``, m."""
    if nacp not in NACP_EPU_M:
        raise UserError(
            f"surveillance.nacp = {nacp!r}; allowed: {min(NACP_EPU_M)}..{max(NACP_EPU_M)}"
        )
    return sigma_from_r95(NACP_EPU_M[nacp]), NACP_VEPU_M[nacp] / R95_PER_SIGMA_1D


def nacv_sigmas(nacv: int) -> tuple[float, float]:
    """(horizontal per-axis, vertical) 1-sigma velocity error of NACv ``nacv``, m/s."""
    if nacv not in NACV_HFOM_MPS:
        raise UserError(
            f"surveillance.nacv = {nacv!r}; allowed: {min(NACV_HFOM_MPS)}..{max(NACV_HFOM_MPS)}"
        )
    return sigma_from_r95(NACV_HFOM_MPS[nacv]), NACV_VFOM_MPS[nacv] / R95_PER_SIGMA_1D


_DEFAULT = SurveillanceSection()  # the schema's defaults (surveillance:), declared there once


@dataclass(frozen=True)
class SurveillanceConfig:
    """As the scenario's ``surveillance`` section (docs/scenario.md). ``sensor`` None: no onboard
    sensor, non-cooperative intruders are not seen at all."""

    model: str = _DEFAULT.model
    rate_hz: float = _DEFAULT.rate_hz
    nacp: int = _DEFAULT.nacp
    nacv: int = _DEFAULT.nacv
    latency_s: float = _DEFAULT.latency_s
    dropout: float = _DEFAULT.dropout
    noncooperative: float = _DEFAULT.noncooperative
    sensor: SensorConfig | None = field(default_factory=SensorConfig)
    # how long the receiver has been listening before the episode's t = 0 (the episode's
    # picture, uavxai.sim.picture.Picture, hears the traffic flown back over that window)
    preroll_s: float = _DEFAULT.preroll_s
    tracker: str = _DEFAULT.tracker  # ekf | imm (uavxai.surveillance.tracker, .imm)

    def __post_init__(self) -> None:
        # The schema's section checks every field (bounds, the model's and the tracker's names):
        # one rule for a scenario's and for a config built in code. The sensor checks its own.
        values = {f.name: getattr(self, f.name) for f in fields(self) if f.name != "sensor"}
        checked(SurveillanceSection, values, "surveillance")

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> SurveillanceConfig:
        """The scenario's ``surveillance`` section, field for field (the schema validated it
        and declares the defaults)."""
        s = scenario.surveillance
        sensor = None if s.sensor is None else SensorConfig(**s.sensor.model_dump())
        return cls(**{**s.model_dump(exclude={"sensor"}), "sensor": sensor})

    @property
    def sigma_pos(self) -> tuple[float, float]:
        """(horizontal per-axis, vertical) 1-sigma position error of the ADS-B reports, m."""
        return nacp_sigmas(self.nacp)

    @property
    def sigma_vel(self) -> tuple[float, float]:
        """(horizontal per-axis, vertical) 1-sigma velocity error of the ADS-B reports, m/s."""
        return nacv_sigmas(self.nacv)


@dataclass(frozen=True)
class Report:
    """One surveillance report: intruder ``id``'s state at ``t_measured`` as received at
    ``t_delivered``. ``vel`` None: a position-only report (the onboard sensor).
    ``sigma_pos`` / ``sigma_vel`` are the per-axis 1-sigma errors (horizontal, vertical)
    the source claims (0: exact). ``emitter``: the ADS-B emitter category the aircraft
    broadcasts (:mod:`uavxai.surveillance.emitters`); None: none (the onboard sensor's, NO_INFO)."""

    id: str
    t_measured: float
    t_delivered: float
    pos: np.ndarray  # (3,) x, y, h
    vel: np.ndarray | None  # (3,) vx, vy, vh, or None
    sigma_pos: tuple[float, float]
    sigma_vel: tuple[float, float]
    source: str  # "adsb" | "sensor" | "truth"
    emitter: str | None = None


def _number(ident: str) -> int:
    tail = ident.rsplit("-", 1)[-1]
    return int(tail) if tail.isdigit() else zlib.crc32(ident.encode()) % (1 << 20)


def is_cooperative(ident: str, share_noncooperative: float, seed: int) -> bool:
    """Whether intruder ``ident`` carries ADS-B: a uniform draw from a stream of its own
    number, so the answer does not depend on which other intruders exist. A fleet's members
    always do (docs/fleet.md: they see each other through ADS-B)."""
    if share_noncooperative <= 0 or is_member(ident):
        return True
    if share_noncooperative >= 1:
        return False
    state = np.random.SeedSequence(seed, spawn_key=(_COOP_STREAM, _number(ident)))
    u = state.generate_state(1, dtype=np.uint64)[0] / 2.0**64
    return bool(u >= share_noncooperative)


class Surveillance:
    """The reports the ownship receives. Call :meth:`observe` with every state the dynamics
    produce (at least ``rate_hz``; the episode's sample rate is right): it samples the due
    reports and returns those whose delivery time has come.

    The ownship is row 0 of the state; intruders are rows 1..N, known by their ids (an id
    seen for the first time gets its report phase and cooperative flag then).
    ``categories``: the emitter category each broadcasts (the episode's aircraft; None:
    every one a UAV).
    """

    def __init__(
        self,
        config: SurveillanceConfig,
        seed: int = 0,
        categories: TrafficCategories | None = None,
    ) -> None:
        self.config = config
        self.seed = int(seed)
        self.categories = categories or TrafficCategories()
        self._rng = np.random.default_rng(
            np.random.SeedSequence(self.seed, spawn_key=(_NOISE_STREAM,))
        )
        self._next_t: dict[str, float] = {}  # next measurement time per intruder
        self._coop: dict[str, bool] = {}
        self._queue: list[Report] = []  # measured, not yet delivered (in measurement order)
        self.sent = 0  # reports measured and sent (before dropout)
        self.lost = 0  # of those, lost (dropout)

    def cooperative(self, ident: str) -> bool:
        c = self._coop.get(ident)
        if c is None:
            c = self._coop[ident] = is_cooperative(ident, self.config.noncooperative, self.seed)
        return c

    def observe(self, state: TrafficState) -> list[Report]:
        """Reports delivered at ``state.t`` (measured at ``state.t - latency`` or earlier)."""
        cfg = self.config
        if state.n < 2:
            return self._release(state.t)
        if cfg.model == "truth":
            return [
                Report(
                    id=state.ids[i],
                    t_measured=state.t,
                    t_delivered=state.t,
                    pos=state.pos[i].copy(),
                    vel=state.vel[i].copy(),
                    sigma_pos=(0.0, 0.0),
                    sigma_vel=(0.0, 0.0),
                    source="truth",
                )
                for i in range(1, state.n)
            ]
        self._measure(state)
        return self._release(state.t)

    def _due(self, state: TrafficState) -> np.ndarray:
        """Rows (1..N) whose report is due at ``state.t``; schedules their next one."""
        period = 1.0 / self.config.rate_hz
        due = []
        for i in range(1, state.n):
            ident = state.ids[i]
            nxt = self._next_t.get(ident)
            if nxt is None:
                # a random phase: transponders are not synchronised with each other
                nxt = state.t + float(self._rng.uniform(0.0, period))
            if state.t >= nxt - 1e-9:
                due.append(i)
                # skip whole periods if the caller's steps are coarser than the rate
                nxt += period * max(1, math.floor((state.t - nxt) / period + 1e-9) + 1)
            self._next_t[ident] = nxt
        return np.asarray(due, dtype=int)

    def _measure(self, state: TrafficState) -> None:
        cfg = self.config
        rows = self._due(state)
        if rows.size == 0:
            return
        coop = np.array([self.cooperative(state.ids[i]) for i in rows], dtype=bool)
        # Draw for every due row, cooperative or not, so that the noise stream does not
        # depend on which intruders are cooperative.
        k = rows.size
        z_pos = self._rng.standard_normal((k, 3))
        z_vel = self._rng.standard_normal((k, 3))
        lost = self._rng.random(k) < cfg.dropout
        t_m = state.t
        sp, sv = cfg.sigma_pos, cfg.sigma_vel
        scale_p = np.array([sp[0], sp[0], sp[1]])
        scale_v = np.array([sv[0], sv[0], sv[1]])
        sensor = cfg.sensor
        seen = sensor_sees(state, rows, sensor) if sensor is not None else np.zeros(k, dtype=bool)
        for j, i in enumerate(rows):
            ident = state.ids[i]
            if coop[j]:
                self.sent += 1
                if lost[j]:
                    self.lost += 1
                    continue
                self._queue.append(
                    Report(
                        id=ident,
                        t_measured=t_m,
                        t_delivered=t_m + cfg.latency_s,
                        pos=state.pos[i] + z_pos[j] * scale_p,
                        vel=state.vel[i] + z_vel[j] * scale_v,
                        sigma_pos=sp,
                        sigma_vel=sv,
                        source="adsb",
                        emitter=self.categories.of(ident),
                    )
                )
            elif seen[j]:
                # The onboard sensor: no transmission, so no latency and no dropout; its own
                # isotropic position noise, no velocity.
                s = sensor.sigma_m  # type: ignore[union-attr]
                self._queue.append(
                    Report(
                        id=ident,
                        t_measured=t_m,
                        t_delivered=t_m,
                        pos=state.pos[i] + z_pos[j] * s,
                        vel=None,
                        sigma_pos=(s, s),
                        sigma_vel=(math.inf, math.inf),
                        source="sensor",
                    )
                )

    def _release(self, t: float) -> list[Report]:
        out = [r for r in self._queue if r.t_delivered <= t + 1e-9]
        if out:
            self._queue = [r for r in self._queue if r.t_delivered > t + 1e-9]
            out.sort(key=lambda r: (r.t_delivered, r.t_measured))
        return out


# ------------------------------------------------------------------------------ MAVLink
# The same address block and flags as the bridge's truth telemetry
# (uavxai.bridges.telemetry), so a ground station sees one kind of traffic.
ICAO_BLOCK = 0xF00000
# A fleet's members ("ownship-i") from a block of their own below it: in the intruders' block
# member i was intruder-i's address, and the receiver merged the two into one track
MEMBER_ICAO_BLOCK = 0xE00000
_MIN_COURSE_SPEED_MPS = 0.5


def icao_address(ident: str) -> int:
    """ICAO address of ``ident``: "intruder-N" -> ICAO_BLOCK + N, fleet member "ownship-i"
    -> MEMBER_ICAO_BLOCK + i."""
    return (MEMBER_ICAO_BLOCK if is_member(ident) else ICAO_BLOCK) + _number(ident)


def ident_from_icao(address: int) -> str:
    address = int(address)
    if MEMBER_ICAO_BLOCK <= address < ICAO_BLOCK:
        return member_id(address - MEMBER_ICAO_BLOCK)
    return f"intruder-{address - ICAO_BLOCK}"


def adsb_fields(report: Report, frame: LocalFrame) -> dict[str, int | bytes]:
    """The ADSB_VEHICLE field values (MAVLink units) of an ADS-B report, as keyword
    arguments of ``MAVLink.adsb_vehicle_send`` / ``MAVLink_adsb_vehicle_message``:
    lat/lon degE7, geometric altitude MSL in mm, course over ground in cdeg, horizontal
    speed cm/s, vertical speed (up) cm/s, ``tslc`` the report's age in whole seconds.
    A position-only report (no velocity) leaves the velocity flags unset."""
    from pymavlink.dialects.v20 import common as mavlink

    lat, lon, alt = frame.to_geodetic(report.pos[0], report.pos[1], report.pos[2])
    flags = (
        mavlink.ADSB_FLAGS_VALID_COORDS
        | mavlink.ADSB_FLAGS_VALID_ALTITUDE
        | mavlink.ADSB_FLAGS_VALID_CALLSIGN
        | mavlink.ADSB_FLAGS_SIMULATED
    )
    heading = hor = ver = 0
    if report.vel is not None:
        vx, vy, vh = (float(v) for v in report.vel)
        speed = math.hypot(vx, vy)
        course = math.atan2(vx, vy) if speed >= _MIN_COURSE_SPEED_MPS else 0.0
        heading = round(math.degrees(course) % 360.0 * 100.0) % 36000
        hor = min(round(speed * 100.0), 0xFFFF)
        ver = max(-0x8000, min(0x7FFF, round(vh * 100.0)))
        flags |= (
            mavlink.ADSB_FLAGS_VALID_HEADING
            | mavlink.ADSB_FLAGS_VALID_VELOCITY
            | mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID
        )
    number = _number(report.id)
    return {
        "ICAO_address": icao_address(report.id),
        "lat": round(float(lat) * 1e7),
        "lon": round(float(lon) * 1e7),
        "altitude_type": mavlink.ADSB_ALTITUDE_TYPE_GEOMETRIC,
        "altitude": round(float(alt) * 1000.0),
        "heading": heading,
        "hor_velocity": hor,
        "ver_velocity": ver,
        "callsign": f"{'UAV' if is_member(report.id) else 'INTR'}{number:02d}"[:8].encode(),
        "emitter_type": emitter_type(report.emitter),
        "tslc": min(255, max(0, round(report.t_delivered - report.t_measured))),
        "flags": flags,
        "squawk": 0,
    }


def adsb_message(report: Report, frame: LocalFrame):
    """A pymavlink ``MAVLink_adsb_vehicle_message`` carrying ``report``."""
    from pymavlink.dialects.v20 import common as mavlink

    return mavlink.MAVLink_adsb_vehicle_message(**adsb_fields(report, frame))


def report_from_adsb(
    msg: object,
    frame: LocalFrame,
    t_received: float,
    config: SurveillanceConfig | None = None,
) -> Report:
    """A decoded ADSB_VEHICLE message (anything with its field names as attributes) back
    into a report. The message carries no time stamp: the state is taken as measured
    ``config.latency_s`` before ``t_received`` (the receiver's known latency), and the
    claimed errors are those of the configured NACp / NACv."""
    from pymavlink.dialects.v20 import common as mavlink

    cfg = config or SurveillanceConfig()
    lat = msg.lat / 1e7  # type: ignore[attr-defined]
    lon = msg.lon / 1e7  # type: ignore[attr-defined]
    alt = msg.altitude / 1000.0  # type: ignore[attr-defined]
    x, y, h = frame.to_local(lat, lon, alt)
    flags = int(msg.flags)  # type: ignore[attr-defined]
    vel = None
    if flags & mavlink.ADSB_FLAGS_VALID_VELOCITY:
        speed = msg.hor_velocity / 100.0  # type: ignore[attr-defined]
        course = math.radians(msg.heading / 100.0)  # type: ignore[attr-defined]
        vh = (
            msg.ver_velocity / 100.0  # type: ignore[attr-defined]
            if flags & mavlink.ADSB_FLAGS_VERTICAL_VELOCITY_VALID
            else 0.0
        )
        vel = np.array([speed * math.sin(course), speed * math.cos(course), vh])
    return Report(
        id=ident_from_icao(msg.ICAO_address),  # type: ignore[attr-defined]
        t_measured=t_received - cfg.latency_s,
        t_delivered=t_received,
        pos=np.array([float(x), float(y), float(h)]),
        vel=vel,
        sigma_pos=cfg.sigma_pos,
        sigma_vel=cfg.sigma_vel if vel is not None else (math.inf, math.inf),
        source="adsb",
        emitter=emitter_category(msg.emitter_type),  # type: ignore[attr-defined]
    )
