"""A snapshot of all aircraft, the one structure that dynamics hands to everyone else.

Frame: local ENU at ``world.origin`` (x east, y north, h up), SI units. Angles in radians:
``phi`` bank (right wing down positive), ``theta`` pitch (nose up positive), ``psi`` heading
clockwise from north. Row 0 is always the ownship; rows 1..N are ``intruder-1`` .. ``intruder-N``.
"""

from __future__ import annotations

from dataclasses import dataclass, replace

import numpy as np

OWNSHIP_ID = "ownship"


def member_id(n: int) -> str:
    """Public name of fleet member ``n`` (0-based; a fleet of one is ``ownship``)."""
    return f"{OWNSHIP_ID}-{n}"


def is_member(ident: str) -> bool:
    """Whether ``ident`` names a fleet member (:func:`member_id`)."""
    return ident.startswith(f"{OWNSHIP_ID}-")


def intruder_id(n: int) -> str:
    """Public name of intruder ``n`` (1-based), as in trajectory.csv and rerun paths."""
    return f"intruder-{n}"


@dataclass(frozen=True)
class TrafficState:
    t: float  # simulated time, s
    ids: tuple[str, ...]  # ("ownship", "intruder-1", ...)
    pos: np.ndarray  # (N, 3) x, y, h  [m]
    vel: np.ndarray  # (N, 3) vx, vy, vh  [m/s]
    att: np.ndarray  # (N, 3) phi, theta, psi  [rad]
    airspeed: np.ndarray  # (N,) true airspeed [m/s]

    @property
    def n(self) -> int:
        return len(self.ids)

    @property
    def ground_speed(self) -> np.ndarray:
        return np.hypot(self.vel[:, 0], self.vel[:, 1])

    def flown_straight(self, t: float) -> TrafficState:
        """Every aircraft moved along its present velocity, in a straight line, to time ``t``
        (earlier or later); attitudes and airspeeds as they are."""
        return replace(self, t=float(t), pos=self.pos + self.vel * (float(t) - self.t))

    def min_separation(self) -> float:
        """Smallest 3-D distance from the ownship to any intruder (inf with no intruders)."""
        if self.n < 2:
            return float("inf")
        return float(np.min(np.linalg.norm(self.pos[1:] - self.pos[0], axis=1)))
