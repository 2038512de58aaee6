"""Pair an intruder track from the encounter model with the ownship into a weighted encounter.

Following the MIT LL encounter generation tool (``mit-ll/em-pairing-uncor-importancesampling``,
``initializeUncorrelatedEncounter.m``), simplified to an ownship given by its state at the time
of closest approach (TCA):

1. an intruder track is sampled from the model (flyable tracks only, see tracks.is_flyable);
2. the TCA is drawn uniformly among the whole seconds of ``config.tca_window``;
3. the approach angle (intruder heading minus ownship heading at TCA) is drawn with a density
   proportional to the relative speed |v_int - v_own| (rejection sampling, as MIT LL: faster
   closing geometries meet more often);
4. the horizontal miss distance (HMD, signed: which side of the relative velocity) and the
   vertical miss distance (VMD = intruder height - ownship height at TCA) are drawn;
5. the track is rotated about its TCA point to the approach angle and translated so that at TCA
   the intruder lies HMD away from the ownship perpendicular to the relative horizontal
   velocity (so TCA is the horizontal closest approach of the straight-line motion) and VMD
   above it. The model's altitude layer still shapes the track's dynamics; its altitude is
   replaced by the ownship's height plus VMD.

Distributions (``importance``):

- nominal, ``"none"``: HMD uniform on [-hmd_max, hmd_max] (MIT LL's ``actual_hmd_w =
  1 / (2 maxHMD)``: for uniformly spread traffic, where a relative straight path passes is
  uniform across it); ``hmd_nominal="disc"`` instead puts the CPA point uniformly over a disc
  of radius hmd_max (|HMD| density 2 r / hmd_max^2). VMD uniform on [-vmd_max, vmd_max].
  HMD and VMD are independent. Weight 1.
- proposal, ``"nmac"``: each of HMD and VMD drawn from a defensive mixture, half the nominal
  and half uniform inside the NMAC cylinder (|HMD| < 152.4 m, |VMD| < 30.48 m): a piecewise
  uniform proposal concentrated under 500 ft / 100 ft as the MIT LL tool's, whose weights stay
  below 4. Weight = nominal density / proposal density of the drawn (HMD, VMD), so that
  sum(w f) / n estimates the nominal mean of f without bias.

``Encounter.flux`` is the mean over approach angles of the relative speed (m/s): MIT LL
multiplies its version (``vrelnorm``) into the weight so that encounters with fast intruders
count more often; it is kept apart here so the importance weight stays nominal / proposal.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Literal

import numpy as np

from uavxai.encounters.model import EncounterModel
from uavxai.encounters.tracks import MIN_FIXED_WING_SPEED, Trajectory, limit_track, sample_track
from uavxai.errors import UserError

NMAC_HMD = 152.4  # m, 500 ft
NMAC_VMD = 30.48  # m, 100 ft
Importance = Literal["none", "nmac"]
# CONUS, other airspace (class E/G), the 50-500 ft AGL layer: where a small UAV flies.
DEFAULT_START = {"G": 0, "A": 3, "L": 0}


@dataclass(frozen=True)
class OwnshipAtTCA:
    """The ownship at the time of closest approach: position (x east, y north, h up; m) and
    velocity (m/s)."""

    position: tuple[float, float, float]
    velocity: tuple[float, float, float]

    def at(self, t: np.ndarray | float, tca: float) -> np.ndarray:
        """Positions at times t of an ownship flying straight through this state at tca."""
        dt = np.asarray(t, dtype=float)[..., None] - tca
        return np.asarray(self.position) + dt * np.asarray(self.velocity)


def straight_ownship(speed: float, heading: float, height: float, tca: float,
                     start: tuple[float, float] = (0.0, 0.0)) -> OwnshipAtTCA:
    """A level ownship leaving ``start`` at t = 0 at ``speed`` (m/s), ``heading`` (rad,
    clockwise from north) and ``height`` (m): its state at t = tca."""
    vx, vy = speed * math.sin(heading), speed * math.cos(heading)
    return OwnshipAtTCA((start[0] + vx * tca, start[1] + vy * tca, height), (vx, vy, 0.0))


@dataclass(frozen=True)
class EncounterConfig:
    duration: int = 120  # s of intruder track
    tca_window: tuple[int, int] = (45, 75)  # s, the TCA is a whole second in it
    hmd_max: float = 1852.0  # m (1 NM)
    vmd_max: float = 152.4  # m (500 ft)
    hmd_nominal: Literal["uniform", "disc"] = "uniform"
    start: dict[str, int] = field(default_factory=lambda: dict(DEFAULT_START))
    min_speed: float = MIN_FIXED_WING_SPEED  # m/s
    steps_per_second: int = 1
    # The intruder aircraft's dynamic limits (tracks.limit_track), applied before placing.
    max_speed: float = math.inf  # m/s
    max_vertical_rate: float = math.inf  # m/s
    max_bank: float = math.inf  # rad: turn rates within g tan(max_bank) / V

    def check(self) -> None:
        lo, hi = self.tca_window
        if not 0 <= lo <= hi < self.duration:
            raise UserError(f"tca_window {self.tca_window} must lie in [0, {self.duration})")
        if self.hmd_max < NMAC_HMD or self.vmd_max < NMAC_VMD:
            raise UserError("hmd_max and vmd_max must cover the NMAC cylinder (152.4, 30.48 m)")
        if self.hmd_nominal not in ("uniform", "disc"):
            raise UserError("hmd_nominal is 'uniform' or 'disc'")


@dataclass(frozen=True)
class Encounter:
    """An intruder trajectory in the local frame against the ownship, with its geometry at TCA
    and its importance weight (nominal / proposal density)."""

    intruder: Trajectory
    ownship: OwnshipAtTCA
    tca: float  # s
    hmd: float  # m, horizontal distance at TCA (>= 0)
    vmd: float  # m, intruder height - ownship height at TCA
    approach_angle: float  # rad, intruder heading - ownship heading at TCA, in [-pi, pi)
    weight: float
    flux: float  # m/s, mean relative speed over approach angles (MIT LL vrelnorm)
    seed: int
    importance: Importance


# -- miss distances and their densities -----------------------------------------------------


def _nominal_hmd(rng: np.random.Generator, n: int, c: EncounterConfig) -> np.ndarray:
    u, sign = rng.random(n), np.where(rng.random(n) < 0.5, -1.0, 1.0)
    r = c.hmd_max * (np.sqrt(u) if c.hmd_nominal == "disc" else u)
    return sign * r


def nominal_density(hmd: np.ndarray, vmd: np.ndarray, c: EncounterConfig) -> np.ndarray:
    """Nominal joint density of signed (HMD, VMD), 1/m^2."""
    a = np.abs(hmd)
    p_h = a / c.hmd_max**2 if c.hmd_nominal == "disc" else np.full_like(a, 0.5 / c.hmd_max)
    p_h = np.where(a <= c.hmd_max, p_h, 0.0)
    p_v = np.where(np.abs(vmd) <= c.vmd_max, 0.5 / c.vmd_max, 0.0)
    return p_h * p_v


def proposal_density(hmd: np.ndarray, vmd: np.ndarray, c: EncounterConfig) -> np.ndarray:
    """The "nmac" proposal: per axis half nominal, half uniform inside the NMAC bound."""
    a = np.abs(hmd)
    p_h = a / c.hmd_max**2 if c.hmd_nominal == "disc" else np.full_like(a, 0.5 / c.hmd_max)
    p_h = np.where(a <= c.hmd_max, p_h, 0.0)
    q_h = 0.5 * p_h + 0.5 * (a <= NMAC_HMD) / (2 * NMAC_HMD)
    p_v = np.where(np.abs(vmd) <= c.vmd_max, 0.5 / c.vmd_max, 0.0)
    q_v = 0.5 * p_v + 0.5 * (np.abs(vmd) <= NMAC_VMD) / (2 * NMAC_VMD)
    return q_h * q_v


def draw_miss_distances(rng: np.random.Generator, n: int, importance: Importance,
                        config: EncounterConfig | None = None
                        ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """n signed HMDs, VMDs (m) and their weights, from the nominal or the "nmac" proposal."""
    c = config or EncounterConfig()
    hmd = _nominal_hmd(rng, n, c)
    vmd = c.vmd_max * (2 * rng.random(n) - 1)
    if importance == "none":
        return hmd, vmd, np.ones(n)
    if importance != "nmac":
        raise UserError(f"importance is 'none' or 'nmac', not {importance!r}")
    inside_h, inside_v = rng.random(n) < 0.5, rng.random(n) < 0.5
    hmd = np.where(inside_h, NMAC_HMD * (2 * rng.random(n) - 1), hmd)
    vmd = np.where(inside_v, NMAC_VMD * (2 * rng.random(n) - 1), vmd)
    return hmd, vmd, nominal_density(hmd, vmd, c) / proposal_density(hmd, vmd, c)


# -- geometry -------------------------------------------------------------------------------


def _relative_speed(angle: np.ndarray, v_own: float, v_int: float, dh: float) -> np.ndarray:
    return np.sqrt((v_int * np.cos(angle) - v_own) ** 2 + (v_int * np.sin(angle)) ** 2 + dh**2)


def draw_approach_angle(rng: np.random.Generator, v_own: float, v_int: float,
                        dh: float) -> float:
    """Intruder minus ownship heading, density proportional to the relative speed (MIT LL)."""
    top = _relative_speed(np.array(math.pi), v_own, v_int, dh)
    for _ in range(10_000):
        a = (rng.random() - 0.5) * 2 * math.pi
        if rng.random() * top <= _relative_speed(np.array(a), v_own, v_int, dh):
            return a
    raise UserError("approach angle: rejection sampling did not accept")  # pragma: no cover


def place_intruder(track: Trajectory, k: int, own: OwnshipAtTCA, hmd: float, vmd: float,
                   approach_angle: float) -> Trajectory:
    """Rotate ``track`` about its sample k to heading (ownship heading + approach_angle) and
    translate it so that at sample k it lies |hmd| from the ownship, perpendicular to the
    relative horizontal velocity (on the side of hmd's sign), and vmd above it."""
    ovx, ovy, _ = own.velocity
    turn = math.atan2(ovx, ovy) + approach_angle - math.atan2(track.vx[k], track.vy[k])
    c, s = math.cos(turn), math.sin(turn)  # clockwise rotation by `turn`

    def rotate(x: np.ndarray, y: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        return x * c + y * s, -x * s + y * c

    x, y = rotate(track.x - track.x[k], track.y - track.y[k])
    vx, vy = rotate(track.vx, track.vy)
    rel = np.array([vx[k] - ovx, vy[k] - ovy])
    norm = float(np.hypot(*rel))
    if norm < 1e-6:  # same velocity: any direction is perpendicular; take the ownship's right
        rel, norm = np.array([ovx, ovy]), max(float(np.hypot(ovx, ovy)), 1e-9)
    side = np.array([rel[1], -rel[0]]) / norm
    px, py, ph = own.position
    return Trajectory(t=track.t, x=px + hmd * side[0] + x, y=py + hmd * side[1] + y,
                      h=ph + vmd + track.h - track.h[k], vx=vx, vy=vy, vh=track.vh)


def sample_encounter(model: EncounterModel,
                     own: OwnshipAtTCA | Callable[[float], OwnshipAtTCA], seed: int,
                     importance: Importance = "none",
                     config: EncounterConfig | None = None) -> Encounter:
    """One encounter, fully determined by ``seed`` (see the module docstring). ``own``: the
    ownship at TCA, or a function of the drawn TCA (s) giving it (an ownship on a path
    flown from t = 0, so that the intruder meets it at that time)."""
    c = config or EncounterConfig()
    c.check()
    rng = np.random.default_rng(seed)
    track = sample_track(model, rng, c.duration, c.start, c.steps_per_second, c.min_speed)
    track = limit_track(track, c.max_speed, c.max_vertical_rate, c.max_bank)
    tca = int(rng.integers(c.tca_window[0], c.tca_window[1] + 1))
    if callable(own):
        own = own(float(tca))
    k = tca * c.steps_per_second
    v_own = math.hypot(own.velocity[0], own.velocity[1])
    dh = float(track.vh[k]) - own.velocity[2]
    angle = draw_approach_angle(rng, v_own, float(track.speed[k]), dh)
    hmd, vmd, w = (float(a[0]) for a in draw_miss_distances(rng, 1, importance, c))
    grid = np.linspace(-math.pi, math.pi, 721)[:-1]
    flux = float(_relative_speed(grid, v_own, float(track.speed[k]), dh).mean())
    intruder = place_intruder(track, k, own, hmd, vmd, angle)
    return Encounter(intruder, own, float(tca), abs(hmd), vmd, angle, w, flux, seed, importance)


def sample_encounters(model: EncounterModel, own: OwnshipAtTCA, n: int, seed: int,
                      importance: Importance = "none",
                      config: EncounterConfig | None = None) -> list[Encounter]:
    """n encounters; encounter i has its own seed (from ``seed``), so that
    ``sample_encounter(model, own, e.seed, importance, config)`` regenerates it alone."""
    if not 0 <= n <= 10_000_000:
        raise UserError("n must be in 0..1e7")
    seeds = np.random.SeedSequence(seed).generate_state(n, dtype=np.uint64)
    return [sample_encounter(model, own, int(s), importance, config) for s in seeds]
