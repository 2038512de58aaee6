"""What watches an episode: files, the recording, metrics, pacing, progress.

Each is an :class:`~uavxai.sim.episode.Observer`, which only observes (what acts is an engine
step: :mod:`uavxai.sim.steps`); adding an output is adding one here, not editing the loop.
Per-sample work is buffered and written in blocks (trajectory rows, channel evaluation), so
watching costs little beside the flight itself.
"""

from __future__ import annotations

import json
import math
import time
from pathlib import Path

import numpy as np

from uavxai.avoidance.types import Ownship
from uavxai.dynamics.state import TrafficState
from uavxai.outputs import write_output
from uavxai.sim.episode import DecisionEvent, Episode, Observer, stats

TRAJECTORY_FIELDS = ("t", "id", "x", "y", "h", "vx", "vy", "vh", "phi", "theta", "psi", "airspeed")
_FLUSH_SAMPLES = 100
# t, id, then position, velocity (mm, mm/s), angles (1e-5 rad), airspeed
_ROW = ("{},{}" + ",{:.3f}" * 6 + ",{:.5f}" * 3 + ",{:.3f}\n").format


class TrajectoryCSV(Observer):
    """``trajectory.csv``: one row per aircraft per sample (README), written in blocks."""

    def __init__(self, path: Path) -> None:
        self._f = path.open("w", newline="")
        self._f.write(",".join(TRAJECTORY_FIELDS) + "\n")
        self._block: list[TrafficState] = []

    def on_start(self, ep: Episode) -> None:
        self._block.append(ep.state)

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        self._block.append(state)
        if len(self._block) >= _FLUSH_SAMPLES:
            self._flush()

    def _flush(self) -> None:
        lines = []
        for s in self._block:
            cols = np.column_stack([s.pos, s.vel, s.att, s.airspeed])
            t = f"{s.t:.4f}".rstrip("0").rstrip(".") or "0"
            for ident, row in zip(s.ids, cols.tolist(), strict=True):
                lines.append(_ROW(t, ident, *row))
        self._f.write("".join(lines))
        self._block.clear()

    def close(self) -> None:
        if not self._f.closed:
            self._flush()
            self._f.close()


def _xyzv(pos: np.ndarray, vel: np.ndarray) -> dict[str, float]:
    values = (*pos.tolist(), *vel.tolist())
    return dict(zip(("x", "y", "h", "vx", "vy", "vh"), (round(v, 3) for v in values), strict=True))


class DecisionsJSONL(Observer):
    """``decisions.jsonl``: one line per decision, what the planner saw and chose (README)."""

    def __init__(self, path: Path) -> None:
        self._f = path.open("w")

    def on_decision(self, ep: Episode, event: DecisionEvent) -> None:
        from uavxai.xai.explain import decision_record

        record = decision_record(event.t, event.own, event.intruders, event.decision)
        if event.applied_t is not None:  # the planner's latency: when its command arrived
            record["applied_t"] = round(event.applied_t, 3)
        truth = event.truth  # the same instant as it really was, beside the belief
        record["truth"] = [
            {"id": truth.ids[i], **_xyzv(truth.pos[i], truth.vel[i])} for i in range(1, truth.n)
        ]
        self._f.write(json.dumps({"step": event.step, **record}, allow_nan=False) + "\n")

    def close(self) -> None:
        self._f.close()


class Trust(Observer):
    """How far what the explanations claim was from what was then flown (``summary.trust``).

    Each decision's sentence quotes its chosen branch's predicted minimum separation
    (``Decision.branch_min_separation_m``: the planned line against the intruders flying on as
    predicted, ``branch_horizon_s`` ahead). Here that number is set against the smallest
    separation really flown (to any aircraft, between samples included) over the same
    window, from the decision to its horizon or the end of the flight;
    ``separation_error_m`` summarises ``|predicted - flown|`` over the decisions.
    """

    def __init__(self) -> None:
        self.errors: list[float] = []
        self._open: list[list[float]] = []  # [end time, predicted, flown so far]

    def on_decision(self, ep: Episode, event: DecisionEvent) -> None:
        d = event.decision
        if math.isfinite(d.branch_min_separation_m) and d.branch_horizon_s > 0:
            self._open.append([event.t + d.branch_horizon_s, d.branch_min_separation_m, math.inf])

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        if not self._open:
            return
        sep = ep.sample_separation_m  # the closest approach since the last sample
        for window in self._open:
            window[2] = min(window[2], sep)
        done = [w for w in self._open if state.t >= w[0] - 1e-9]
        self._close(done)

    def _close(self, windows: list[list[float]]) -> None:
        for w in windows:
            if math.isfinite(w[2]):
                self.errors.append(abs(w[1] - w[2]))
            self._open.remove(w)

    def on_end(self, ep: Episode, summary: dict) -> None:
        self._close(list(self._open))  # the flight ended first: what was flown until then
        summary["trust"] = {"separation_error_m": stats(self.errors, ("mean", "p95", "max"))}


class OwnPath(Observer):
    """The ownship at every decision and the action it chose: what
    :func:`uavxai.avoidance.model.model_drift` replays to measure how far the aircraft strays
    from the planner's model of it."""

    def __init__(self) -> None:
        self.own: list[Ownship] = []
        self.actions: list[int] = []

    def on_decision(self, ep: Episode, event: DecisionEvent) -> None:
        self.own.append(event.own)
        self.actions.append(int(event.decision.action))


class Throughput(Observer):
    """In-flight throughput: the sum rate at the ownship's position (the service plan's
    users and powers) integrated over the flight. Positions are kept per sample and the
    channel evaluated once per decision period, vectorised over them."""

    def __init__(self, channel, power_w: np.ndarray) -> None:
        self.channel = channel
        self.power_w = np.asarray(power_w, dtype=float)
        self.bits = 0.0
        self._pending: list[np.ndarray] = []  # ownship positions not yet evaluated
        self._sample_s = 0.0

    def on_start(self, ep: Episode) -> None:
        self._sample_s = ep.clock.sample_s

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        self._pending.append(state.pos[0].copy())

    def on_period(self, ep: Episode, event: DecisionEvent, flown_min_m: float) -> None:
        self._evaluate()

    def on_end(self, ep: Episode, summary: dict) -> None:
        self._evaluate()  # an interrupted period
        summary["throughput_in_flight_bits"] = self.bits

    def _evaluate(self) -> None:
        if self._pending:
            rates = self.channel.sum_rate_bps(np.array(self._pending), self.power_w)
            for rate in rates.tolist():  # summed in sample order, as the flight went
                self.bits += rate * self._sample_s
            self._pending.clear()


class Rerun(Observer):
    """The rerun recording: traffic every sample, tree/plan/explanation every decision,
    scalar metrics (docs/recording/README.md)."""

    def __init__(self, recorder, setup: dict) -> None:
        self.recorder = recorder
        self._setup = setup
        self._ms = 0.0
        self._ids: list[str] = []
        self._points = 0  # service points already recorded

    def on_start(self, ep: Episode) -> None:
        self._ids = list(ep.state.ids[1:])
        self.recorder.log_setup(intruder_ids=self._ids, goal=np.asarray(ep.goal), **self._setup)
        self.recorder.ready()  # a recorder process has started (set-up, not flight, time)

    def on_decision(self, ep: Episode, event: DecisionEvent) -> None:
        from uavxai.recording.mission_log import tracks_of

        self._ms = event.decision.ms
        self.recorder.log_decision(event.step, event.t, event.decision, self._ids)
        self.recorder.log_tracks(event.t, *tracks_of(event.intruders))  # belief beside truth

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        rec, m, t = self.recorder, ep.mission, state.t
        rec.log_sample(state, self._ms)  # the traffic and the metrics derived from it
        if "users_xyz" in ep.sample_metrics:
            qos = ep.sample_metrics.get("qos_bps", 0.0)
            rates = ep.sample_metrics["user_rates_bps"]
            uav = ep.sample_metrics.get("user_uav_xyz", state.pos[0])  # a fleet: each user's
            rec.log_users(t, ep.sample_metrics["users_xyz"], rates, qos, uav)
        route = ep.operator.route if ep.operator is not None else None
        if route is not None:  # the operator's mode flies, the mission waits
            rec.log_phase(t, f"{ep.operator.mode.value} (operator)")
        elif m is not None:
            rec.log_phase(t, m.phase.value)
        if m is not None:
            c = m.config
            rec.log_orbit(t, c.station if m.serving else None, c.radius_m)
            while self._points < len(m.service_points):
                _, *xyz = m.service_points[self._points]
                rec.log_service_point(t, np.asarray(xyz))
                self._points += 1

    def close(self) -> None:
        self.recorder.close()

    def member(self, j: int) -> Observer:
        """Fleet member ``j``'s observer of this recording (:class:`MemberRerun`)."""
        return MemberRerun(self.recorder)


class MemberRerun(Observer):
    """A fleet member's decisions in the run's recording (member 0's :class:`Rerun` draws the
    traffic, every member included, and closes the recorder): its plan and explanation."""

    def __init__(self, recorder) -> None:
        self.recorder = recorder

    def on_decision(self, ep: Episode, event: DecisionEvent) -> None:
        ids = ep.state.ids  # the member's view: its own row first
        self.recorder.log_member_decision(ids[0], event.step, event.t, event.decision,
                                          list(ids[1:]))  # fmt: skip


class SummaryJSON(Observer):
    """``summary.json``: the episode's summary plus ``extra`` (what the run knows beside the
    flight: the service point, versions), written whole (temporary file + rename) when the
    episode closes its observers, last of them. It belongs to the episode's save, during which
    a signal waits (:meth:`Episode.run`): an interrupted run still ends with it."""

    def __init__(self, path: Path, extra: dict) -> None:
        self.path = path
        self._extra = extra
        self._summary: dict | None = None

    def on_end(self, ep: Episode, summary: dict) -> None:
        summary.update(self._extra)  # the episode's result carries them too
        self._summary = summary

    def close(self) -> None:
        if self._summary is not None:
            write_output(self.path, json.dumps(self._summary, indent=2) + "\n")


class Pacing(Observer):
    """Holds simulated time to ``factor`` times the wall clock (``--realtime``)."""

    def __init__(self, factor: float) -> None:
        self.factor = factor

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        lag = state.t / self.factor - (time.perf_counter() - ep.wall0)
        if lag > 0:
            time.sleep(lag)


class ProgressBar(Observer):
    """One task of a rich progress bar, advanced per decision. Its total is what the episode
    is expected to fly: the decisions taken so far and an estimate of those left (the legs
    still to fly, at the ground speed flown on legs so far, and the time left on station),
    refined every decision; at the end, the decisions flown, so that the bar ends full."""

    def __init__(self, progress, name: str, total: int) -> None:
        self.progress = progress
        self.name = name
        self.task = progress.add_task(name, total=total)
        self._last: tuple[float, float, float] | None = None  # t, x, y at the last period
        self._leg_m = self._leg_s = 0.0  # flown on legs (not while serving): their speed

    def on_start(self, ep: Episode) -> None:
        self._last = (ep.state.t, *map(float, ep.state.pos[0, :2]))
        self.progress.update(self.task, total=expected_steps(ep, self._speed(ep)))

    def on_period(self, ep: Episode, event: DecisionEvent, flown_min_m: float) -> None:
        t, x, y = ep.state.t, *map(float, ep.state.pos[0, :2])
        if self._last is not None and (ep.mission is None or not ep.mission.serving):
            self._leg_m += math.hypot(x - self._last[1], y - self._last[2])
            self._leg_s += t - self._last[0]
        self._last = (t, x, y)
        self.progress.update(
            self.task,
            advance=1,
            total=expected_steps(ep, self._speed(ep)),
            description=f"{self.name} t={t:5.0f}s",
        )

    def _speed(self, ep: Episode) -> float:
        """The ground speed of the legs flown so far (the planner may fly them faster or
        slower than cruise); before 5 s of them, the airspeed now."""
        if self._leg_s >= 5.0:
            return self._leg_m / self._leg_s
        return float(ep.state.airspeed[0])

    def on_end(self, ep: Episode, summary: dict) -> None:
        self.progress.update(
            self.task,
            total=ep.steps,
            completed=ep.steps,
            description=f"{self.name}: {summary['outcome']}",
        )


def expected_steps(ep: Episode, speed_mps: float) -> int:
    """Decisions the episode will take in all, as far as can be told now: those taken, plus
    the remaining flight (a mission's legs and time on station, or the way to the goal) at
    ``speed_mps`` on the legs, one decision per period; never more than the episode's
    budget."""
    own = ep.state.pos[0]
    speed = max(float(speed_mps), 1.0)
    if ep.mission is not None:
        left_s = ep.mission.remaining_s(own, speed, ep.judge.goal_radius_m)
    else:
        gap = math.dist(own[:2], ep.goal[:2]) - ep.judge.goal_radius_m
        left_s = max(gap, 0.0) / speed
    left = math.ceil(left_s / ep.clock.decision_s)
    return min(ep.steps + max(left, 1), ep.max_steps)
