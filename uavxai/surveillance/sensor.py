"""The onboard sensor that sees non-cooperative traffic (a radar or camera, simplified).

It measures position only (no velocity: the tracker estimates it), within a range and a
horizontal field of view centred on the ownship's heading, with isotropic Gaussian noise.
Its reports are not transmitted, so they have no latency and no dropout. It is told which
intruder it sees (perfect association): the tracker needs no data association.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numpy as np

from uavxai.dynamics.state import TrafficState
from uavxai.geometry import wrap_angle
from uavxai.scenario import Sensor, checked

_DEFAULT = Sensor()  # the schema's defaults (surveillance.sensor), declared there once


@dataclass(frozen=True)
class SensorConfig:
    """The onboard sensor that sees non-cooperative traffic (radar or camera, simplified):
    position only, within ``range_m`` and ``fov_deg`` (total, centred on the ownship's
    heading, horizontal), with per-axis noise ``sigma_m``, at the surveillance rate."""

    range_m: float = _DEFAULT.range_m
    fov_deg: float = _DEFAULT.fov_deg
    sigma_m: float = _DEFAULT.sigma_m

    def __post_init__(self) -> None:
        # The schema's section checks every field: one rule for a scenario's sensor and for
        # one built in code.
        checked(Sensor, {f.name: getattr(self, f.name) for f in fields(self)},
                "surveillance.sensor")


def sensor_sees(state: TrafficState, rows: np.ndarray, sensor: SensorConfig) -> np.ndarray:
    """Which of ``rows`` the onboard sensor of the ownship (row 0) sees: within ``range_m``
    (3-D) and within ``fov_deg / 2`` of the ownship's heading (horizontal bearing)."""
    rows = np.asarray(rows, dtype=int)
    d = state.pos[rows] - state.pos[0]
    in_range = np.linalg.norm(d, axis=1) <= sensor.range_m
    bearing = np.arctan2(d[:, 0], d[:, 1])  # clockwise from north
    off = np.abs(wrap_angle(bearing - state.att[0, 2]))
    in_fov = off <= math.radians(sensor.fov_deg) / 2 + 1e-12
    return in_range & in_fov
