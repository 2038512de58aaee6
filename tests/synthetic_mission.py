"""A made-up mission for the recording tests, benchmark and docs screenshot (no JSBSim).

The ownship flies to a station, orbits it serving walking users, avoids once, moves its orbit
to a new service point as the users drift, and heads home. Rates follow a free-space link
(Shannon over distance), so users far from the orbit fall below the QoS rate and colours
change. Intruders come from :func:`uavxai.recording.synthetic.traffic`; the planner's tracks
are the truth plus a noise whose sigma grows with the age of the last report.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.recording import synthetic

ORIGIN = LocalFrame(47.3977, 8.5456, 400.0)  # any place: the map view needs a real one
QOS_BPS = 2.0e6
BANDWIDTH_HZ = 1.0e6
SNR_AT_1M = 1.0e6  # so the rate at 300 m is just under 2 Mbit/s per user
HOME = np.array([150.0, 150.0, 120.0])
STATIONS = (np.array([1000.0, 1000.0, 120.0]), np.array([1080.0, 940.0, 120.0]))
ORBIT_RADIUS_M = 200.0
SPEED = 20.0
# The flight area the camera frames: the station's surroundings (home lies outside it).
BOUNDS = {"x": (300.0, 1700.0), "y": (300.0, 1700.0), "h": (50.0, 300.0)}


@dataclass
class Sample:
    t: float
    state: TrafficState
    users: np.ndarray  # (K, 3)
    rate_bps: np.ndarray  # (K,)
    phase: str
    orbit: tuple[np.ndarray, float] | None
    service_point: np.ndarray | None  # set when a new one is chosen
    track_ids: list[str]
    track_pos: np.ndarray
    track_sigma: np.ndarray


def rates(uav: np.ndarray, users: np.ndarray) -> np.ndarray:
    d2 = np.sum((users - uav) ** 2, axis=1)
    return BANDWIDTH_HZ * np.log2(1.0 + SNR_AT_1M / d2)


def mission(
    duration_s: float = 180.0, n_intruders: int = 6, k_users: int = 8, seed: int = 0
) -> list[Sample]:
    rng = np.random.default_rng(seed)
    traffic = list(synthetic.traffic(n_intruders, duration_s, seed=seed))
    users = synthetic.users(k_users, seed=seed)
    walk = rng.normal(0.0, 1.0, (k_users, 3)) * np.array([1.0, 1.0, 0.0])
    pos = HOME.copy()
    phase, station, angle = "transit", STATIONS[0], 0.0
    out: list[Sample] = []
    last_report = -1.0
    belief = np.zeros((n_intruders, 3))
    for state in traffic:
        t = state.t
        new_sp = None
        if phase == "transit":
            to = station - pos
            to[2] = 0
            dist = float(np.linalg.norm(to))
            if dist <= ORBIT_RADIUS_M:
                phase, new_sp = "on_station", station
                angle = math.atan2(pos[0] - station[0], pos[1] - station[1])
            else:
                pos = pos + to / dist * SPEED * 0.1
        elif phase in ("on_station", "avoiding"):
            angle += SPEED / ORBIT_RADIUS_M * 0.1
            r = ORBIT_RADIUS_M * (1.3 if phase == "avoiding" else 1.0)
            pos = station + np.array([r * math.sin(angle), r * math.cos(angle), 0.0])
            if phase == "on_station" and 70.0 <= t < 85.0:
                phase = "avoiding"
            elif phase == "avoiding" and t >= 85.0:
                phase = "on_station"
            if t >= duration_s - 30.0:
                phase = "returning"
            elif station is STATIONS[0] and t >= 110.0:  # users drifted: re-plan the point
                station, new_sp = STATIONS[1], STATIONS[1]
        else:
            to = HOME - pos
            pos = pos + to / max(float(np.linalg.norm(to)), 1e-9) * SPEED * 0.1
        s = TrafficState(t, state.ids, state.pos.copy(), state.vel, state.att, state.airspeed)
        s.pos[0] = pos
        users = users + walk * 0.1
        if t - last_report >= 1.0:  # a report a second; belief drifts between reports
            belief = s.pos[1:] + rng.normal(0.0, 8.0, (n_intruders, 3)) * [1, 1, 0]
            last_report = t
        age = t - last_report
        on_orbit = phase in ("on_station", "avoiding")
        out.append(
            Sample(
                t=t,
                state=s,
                users=users.copy(),
                rate_bps=rates(pos, users) if phase != "transit" else np.zeros(k_users),
                phase=phase,
                orbit=(station, ORBIT_RADIUS_M) if on_orbit else None,
                service_point=new_sp,
                track_ids=list(s.ids[1:]),
                track_pos=belief + s.vel[1:] * age,
                track_sigma=np.full(n_intruders, 8.0 + 4.0 * age),
            )
        )
    return out


def record(path: Path | None, samples: list[Sample], recording_id: str = "mission"):
    """Log ``samples`` the way the engine does: every sample, a decision each second."""
    from uavxai.recording.recorder import RunRecorder

    ids = list(samples[0].state.ids[1:])
    rec = RunRecorder(path, recording_id=recording_id)
    rec.log_setup(
        bounds=BOUNDS,
        users=samples[0].users,
        service_point=None,
        search_path=None,
        intruder_ids=ids,
        goal=STATIONS[0],
        origin=ORIGIN,
    )
    for i, s in enumerate(samples):
        if i % 10 == 0:
            d = synthetic.decision(s.state, i // 10)
            rec.log_decision(i // 10, s.t, d, ids)
            rec.log_tracks(s.t, s.track_ids, s.track_pos, s.track_sigma)
        rec.log_traffic(s.state)
        rec.log_phase(s.t, s.phase, why="synthetic")
        if s.orbit is not None:
            rec.log_orbit(s.t, *s.orbit)
        else:
            rec.log_orbit(s.t, None, 0.0)
        if s.service_point is not None:
            rec.log_service_point(s.t, s.service_point)
        rec.log_users(s.t, s.users, s.rate_bps, QOS_BPS, s.state.pos[0])
        rec.log_metrics(
            s.t,
            sum_rate_bps=float(s.rate_bps.sum()),
            min_separation_m=min(s.state.min_separation(), 1e4),
            bank_deg=math.degrees(float(s.state.att[0, 0])),
            airspeed_mps=float(s.state.airspeed[0]),
            decision_ms=10.0,
        )
    rec.close()
    return rec


if __name__ == "__main__":
    import sys

    record(Path(sys.argv[1] if len(sys.argv) > 1 else "mission.rrd"), mission())
