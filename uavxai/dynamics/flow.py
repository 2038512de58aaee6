"""Traffic that persists (`intruders.flow: replace`): an intruder that leaves the flight area
is replaced by a new one entering at the edge, so the traffic density stays constant over long
runs instead of draining away (without it, 2 of 20 straight-flying intruders are still inside
after 100 s in a 2 km box, none after 400 s).

Pure numpy and independent of the dynamics, so the JSBSim world and the kinematic model ask
the same question ("which rows left, and what enters instead?") and get the same answer for the
same seed. A newcomer gets the next intruder number (intruder-21, intruder-22, ... after 20):
ids are never reused, so a track, a trail or a trajectory row always means one aircraft.

Where newcomers enter: uniformly along the perimeter, with the direction drawn from the
cosine law about the inward normal (pdf cos(theta) on (-90, 90) degrees). That is the flux
through a boundary of an isotropic field of straight-flying aircraft with uniform density, so
replacing leavers this way keeps the field uniform and isotropic (the test checks it).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from uavxai.errors import UserError
from uavxai.scenario import Scenario

# A newcomer never appears closer than this to the ownship (horizontally): real traffic does
# not materialise in the sky next to anyone; at 1 km a 30 m/s intruder is at least 17 s from
# a head-on meeting, time for the surveillance picture to hold a track of it. (Every point of
# the area has perimeter points this far away in a 2 km box.)
ENTRY_CLEARANCE_M = 1000.0


def entry_clearance(x_bounds: tuple[float, float], y_bounds: tuple[float, float]) -> float:
    """ENTRY_CLEARANCE_M, or half the area's smaller side in a smaller area (from any point
    some perimeter point is at least that far: an entry can always be drawn)."""
    half = 0.5 * min(x_bounds[1] - x_bounds[0], y_bounds[1] - y_bounds[0])
    return min(ENTRY_CLEARANCE_M, 0.999 * half)


_FLOW_STREAM = 0x464C4F  # "FLO": spawn key apart from the run's other random streams


@dataclass(frozen=True)
class Entry:
    """A new intruder entering at the edge."""

    number: int  # N of intruder-N
    x: float
    y: float
    h: float
    heading_rad: float  # clockwise from north
    speed_mps: float
    replaces: int = -1  # the row it takes over (-1: none given)

    @property
    def id(self) -> str:
        return f"intruder-{self.number}"

    @property
    def heading_deg(self) -> float:
        return math.degrees(self.heading_rad) % 360.0

    @property
    def velocity(self) -> np.ndarray:
        s = self.speed_mps
        return np.array([s * math.sin(self.heading_rad), s * math.cos(self.heading_rad), 0.0])

    def to_spec(self, behaviour: str | None = None):
        """As a scenario ``IntruderSpec`` (what the worlds build intruders from)."""
        from uavxai.scenario import IntruderSpec

        return IntruderSpec(
            x=self.x,
            y=self.y,
            h=self.h,
            heading_deg=self.heading_deg,
            speed_mps=self.speed_mps,
            behaviour=behaviour,
        )


class TrafficFlow:
    """Replaces intruders that left the box ``x_bounds`` x ``y_bounds`` (by more than
    ``margin_m``) with newcomers at its edge, at a height and speed drawn uniformly from
    ``altitude_m`` and ``speed_mps``. ``first_number`` is the number the first newcomer gets
    (the initial count + 1)."""

    def __init__(
        self,
        x_bounds: tuple[float, float],
        y_bounds: tuple[float, float],
        *,
        altitude_m: tuple[float, float] = (100.0, 140.0),
        speed_mps: tuple[float, float] = (15.0, 30.0),
        first_number: int = 1,
        seed: int = 0,
        margin_m: float = 0.0,
    ) -> None:
        (x0, x1), (y0, y1) = map(float, x_bounds), map(float, y_bounds)  # type: ignore[misc]
        if not (x0 < x1 and y0 < y1):
            raise UserError(f"TrafficFlow: empty area x {x_bounds}, y {y_bounds}")
        if not (altitude_m[0] <= altitude_m[1] and 0 < speed_mps[0] <= speed_mps[1]):
            raise UserError(
                f"TrafficFlow: altitude_m {altitude_m} and speed_mps {speed_mps} must be "
                "(min, max) ranges, speeds > 0"
            )
        if margin_m < 0:
            raise UserError(f"TrafficFlow: margin_m must be >= 0, got {margin_m}")
        self.x_bounds, self.y_bounds = (x0, x1), (y0, y1)
        self.altitude_m = tuple(map(float, altitude_m))
        self.speed_mps = tuple(map(float, speed_mps))
        self.margin_m = float(margin_m)
        self.next_number = int(first_number)
        self._rng = np.random.default_rng(np.random.SeedSequence(seed, spawn_key=(_FLOW_STREAM,)))
        self.entered = 0

    @classmethod
    def from_scenario(
        cls, scenario: Scenario, seed: int | None = None, first_number: int | None = None
    ) -> TrafficFlow | None:
        """The flow of a scenario, or None with ``intruders.flow: none`` (the schema checks
        the name)."""
        ic = scenario.intruders
        if ic.flow == "none":
            return None
        w = scenario.world
        if first_number is None:
            first_number = (len(ic.list) if ic.list is not None else int(ic.count)) + 1
        return cls(
            tuple(w.x),
            tuple(w.y),
            altitude_m=tuple(ic.altitude_m),
            speed_mps=tuple(ic.speed_mps),
            first_number=first_number,
            seed=scenario.seed if seed is None else int(seed),
        )

    def left(self, pos: np.ndarray) -> np.ndarray:
        """(N,) bool: which of the positions ``pos`` (N, >= 2) are outside the box by more
        than the margin, horizontally."""
        pos = np.asarray(pos, dtype=float).reshape(-1, np.shape(pos)[-1])
        m = self.margin_m
        (x0, x1), (y0, y1) = self.x_bounds, self.y_bounds
        x, y = pos[:, 0], pos[:, 1]
        return (x < x0 - m) | (x > x1 + m) | (y < y0 - m) | (y > y1 + m)

    def entry(self, replaces: int = -1) -> Entry:
        """A newcomer at the edge, heading inward (cosine law about the inward normal)."""
        rng = self._rng
        (x0, x1), (y0, y1) = self.x_bounds, self.y_bounds
        wx, wy = x1 - x0, y1 - y0
        s = float(rng.uniform(0.0, 2.0 * (wx + wy)))  # arc length along the perimeter
        # (point, inward normal as a heading clockwise from north)
        if s < wx:  # south edge, inward = north
            x, y, normal = x0 + s, y0, 0.0
        elif s < wx + wy:  # east edge, inward = west
            x, y, normal = x1, y0 + (s - wx), 1.5 * math.pi
        elif s < 2 * wx + wy:  # north edge, inward = south
            x, y, normal = x1 - (s - wx - wy), y1, math.pi
        else:  # west edge, inward = east
            x, y, normal = x0, y1 - (s - 2 * wx - wy), 0.5 * math.pi
        theta = math.asin(float(rng.uniform(-1.0, 1.0)))  # pdf cos(theta)/2 on (-pi/2, pi/2)
        entry = Entry(
            number=self.next_number,
            x=float(x),
            y=float(y),
            h=float(rng.uniform(*self.altitude_m)),
            heading_rad=(normal + theta) % (2 * math.pi),
            speed_mps=float(rng.uniform(*self.speed_mps)),
            replaces=replaces,
        )
        self.next_number += 1
        self.entered += 1
        return entry

    def replace(
        self,
        pos: np.ndarray,
        keep_clear: np.ndarray | None = None,
        min_distance_m: float = 0.0,
    ) -> list[Entry]:
        """One newcomer per row of ``pos`` (intruders only, (N, >= 2)) that left the box,
        in row order; ``Entry.replaces`` is that row (0-based into ``pos``). ``keep_clear``
        and ``min_distance_m`` as in :meth:`enter`."""
        return self.enter(np.flatnonzero(self.left(pos)), keep_clear, min_distance_m)

    def enter(
        self,
        rows: np.ndarray | list[int],
        keep_clear: np.ndarray | None = None,
        min_distance_m: float = 0.0,
    ) -> list[Entry]:
        """One newcomer for each of ``rows`` (0-based intruder rows: ones that left, or an
        intruder lost in a crash), in that order.

        ``keep_clear`` (M, >= 2) are points (the ownship) that no newcomer may appear within
        ``min_distance_m`` of, horizontally: an aircraft materialising next to the ownship
        would be a collision nobody could avoid. Entries are redrawn until clear (at most
        1000 times; a UserError if the whole edge is too close)."""
        clear = None if keep_clear is None else np.asarray(keep_clear, dtype=float)[:, :2]
        out = []
        for i in rows:
            for _attempt in range(1000):
                e = self.entry(replaces=int(i))
                if (
                    clear is None
                    or min_distance_m <= 0
                    or np.all(np.hypot(clear[:, 0] - e.x, clear[:, 1] - e.y) >= min_distance_m)
                ):
                    break
                self.next_number -= 1  # a redraw keeps the number
                self.entered -= 1
            else:
                raise UserError(
                    f"no edge point at least {min_distance_m:g} m from the ownship to replace "
                    "an intruder that left the area"
                )
            out.append(e)
        return out


def apply_entries(
    ids: list[str], pos: np.ndarray, vel: np.ndarray, entries: list[Entry]
) -> tuple[list[str], np.ndarray, np.ndarray]:
    """Arrays of intruders with each entry written over the row it replaces (for models
    that keep intruders as arrays, like the kinematic world). Returns new arrays."""
    ids, pos, vel = list(ids), np.array(pos, dtype=float), np.array(vel, dtype=float)
    for e in entries:
        ids[e.replaces] = e.id
        pos[e.replaces, :3] = (e.x, e.y, e.h)
        vel[e.replaces, :3] = e.velocity
    return ids, pos, vel
