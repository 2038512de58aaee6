"""RunRecorder: everything a run shows in rerun (docs/recording/README.md), written cheaply.

Per-frame traffic and metric series are buffered and sent as columns; writing to a file, they
go out every ``FILE_FLUSH_S`` of simulated time (bounded memory, and a crash still leaves a
readable recording); with a live viewer every ``LIVE_FLUSH_S`` so it keeps up. Decisions are
rare (about 1 Hz) and are logged as they come.

Each recorder owns its own ``rr.RecordingStream``, so several in one process stay apart.
"""

from __future__ import annotations

import functools
import logging
import math
import os
import sys
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path
from types import TracebackType

import numpy as np
import rerun as rr

from uavxai.avoidance.types import Decision
from uavxai.comms.channel import Channel
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.recording import entities as ent
from uavxai.recording.aircraft_model import aircraft_mesh
from uavxai.recording.blueprint import default_blueprint
from uavxai.recording.mission_log import MissionLog
from uavxai.recording.traffic_log import TrafficLog, aircraft_paths, member_rows
from uavxai.recording.tree_graph import tree_graph

log = logging.getLogger(__name__)
FILE_FLUSH_S = 30.0
LIVE_FLUSH_S = 0.5

OWNSHIP_COLOR = (255, 165, 0)
TRAIL_POINTS = 1.5  # trail width, ui points
INTRUDER_COLOR = (220, 60, 60)
PLAN_COLOR = (46, 204, 113)


class RunRecorder:
    """Write a run to ``path`` (an .rrd) and/or a spawned viewer; ``close()`` when done."""

    def __init__(
        self,
        path: Path | None,
        spawn: bool = False,
        recording_name: str = "uavxai",
        recording_id: str | None = None,
    ) -> None:
        self.path = Path(path) if path is not None else None
        self.enabled = self.path is not None or spawn
        self._stream = rr.RecordingStream(recording_name, recording_id=recording_id)
        self._flush_period_s = LIVE_FLUSH_S if spawn else FILE_FLUSH_S
        self._traffic = TrafficLog(self._stream)
        self._mission = MissionLog(self._stream)
        self._metrics: dict[str, list[tuple[float, int, float]]] = defaultdict(list)
        self._decision = 0
        self._link: tuple[Channel, np.ndarray] | None = None  # see log_setup
        self._last_flush_t = -math.inf
        self._last_t = -math.inf  # the latest sim time seen, where the run ends on close
        self._closed = False
        self._spawn = spawn
        self._sinks_open = False
        if self.enabled:
            self._log_styles()

    def _open_sinks(
        self, bounds: dict[str, tuple[float, float]] | None, member_trails: Sequence[str] = ()
    ) -> None:
        """Attach the file and/or viewer, with the blueprint framed on ``bounds`` (and a
        fleet's ``member_trails`` drawn whole).

        Deferred until the bounds are known; what was logged before waits in the stream's
        buffer and goes out to the sinks when they are attached.
        """
        if self._sinks_open:
            return
        self._sinks_open = True
        sinks: list[rr.FileSink | rr.GrpcSink] = []
        if self._spawn and self._spawn_viewer():
            sinks.append(rr.GrpcSink())
        if self.path is not None:
            self.path.parent.mkdir(parents=True, exist_ok=True)
            sinks.append(rr.FileSink(self.path))
        # The blueprint must go with the sinks: one given only at init is not written to files.
        blueprint = default_blueprint(bounds, member_trails)
        self._stream.set_sinks(*sinks, default_blueprint=blueprint)

    def _spawn_viewer(self) -> bool:
        """Start the rerun viewer installed with rerun-sdk (next to this Python, so an
        unactivated venv finds it too); a viewer that cannot start costs the live view, never
        the run or its recording file."""
        here = str(Path(sys.executable).parent)
        if here not in os.environ.get("PATH", "").split(os.pathsep):
            os.environ["PATH"] = here + os.pathsep + os.environ.get("PATH", "")
        try:
            self._stream.spawn(connect=False)
        except Exception as exc:  # noqa: BLE001 - no viewer (no display, not installed)
            log.warning("cannot start the rerun viewer (%s); recording to the file only", exc)
            self._spawn = False
            return False
        return True

    def _log_styles(self) -> None:
        log = self._stream.log
        log(ent.WORLD, rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._log_own_styles(ent.OWNSHIP)
        trail_radius = rr.Radius.ui_points(TRAIL_POINTS)
        log(ent.INTRUDER_TRAILS, _line_style((*INTRUDER_COLOR, 160), trail_radius), static=True)
        log(ent.PLAN, _line_style(PLAN_COLOR, rr.Radius.ui_points(3.0)), static=True)
        for name in ent.METRIC_NAMES:
            log(ent.metric_path(name), rr.SeriesLines(names=name, widths=2.0), static=True)
        # Users move (log_users): only their style is static; static positions would hide the
        # moving ones, as static data shadows a timeline.
        # Labels (user number and rate) on hover only: ten overlapping labels hide the scene;
        # the rate bars carry the numbers.
        log(ent.USERS, rr.Points3D.from_fields(radii=[12.0], show_labels=False), static=True)
        log(ent.SERVICE_POINT, rr.Points3D.from_fields(radii=[18.0]), static=True)
        self._mission.log_styles()

    # ---- the pipeline's calls -------------------------------------------------------------

    def log_setup(
        self,
        bounds: dict[str, tuple[float, float]],
        users: np.ndarray,
        service_point: np.ndarray | None,
        search_path: np.ndarray | None,
        intruder_ids: list[str],
        goal: np.ndarray,
        origin: LocalFrame | object | None = None,
        link: tuple[Channel, np.ndarray] | None = None,
    ) -> None:
        """The static scene: flight area, users, service point and its search, goal, models.

        ``link`` (the channel and the service plan's powers) gives :meth:`log_sample` the
        sum rate at the ownship's position, computed here, off the simulation's core.

        ``origin`` (a LocalFrame, or the scenario's ``world.origin``) turns on the map view:
        aircraft, users, orbit and service points are then also logged as GeoPoints. Users and
        the service point are logged at t = 0 (not static), so ``log_users`` and
        ``log_service_point`` can move them.
        """
        if not self.enabled:
            return
        self._link = link
        if origin is not None:
            frame = origin if isinstance(origin, LocalFrame) else LocalFrame.from_origin(origin)
            self._mission.frame = frame
        ids = ("ownship", *intruder_ids)
        paths, members = aircraft_paths(ids), member_rows(ids)
        self._open_sinks(bounds, [ent.trail_path(paths[n]) for n in members])
        log = self._stream.log
        self._stream.set_time(ent.SIM_TIME, duration=0.0)
        self._stream.set_time(ent.DECISION, sequence=self._decision)
        lo = np.array([bounds["x"][0], bounds["y"][0], bounds["h"][0]], dtype=np.float64)
        hi = np.array([bounds["x"][1], bounds["y"][1], bounds["h"][1]], dtype=np.float64)
        box = rr.Boxes3D(
            mins=[lo],
            sizes=[hi - lo],
            colors=[(150, 150, 150)],
            fill_mode="MajorWireframe",
            radii=rr.Radius.ui_points(1.0),
        )
        log(ent.BOUNDS, box, static=True)
        users = np.atleast_2d(np.asarray(users, dtype=np.float64))
        labels = [f"user {i + 1}" for i in range(len(users))]
        log(
            ent.USERS,
            rr.Points3D.from_fields(positions=users, colors=[(52, 152, 219)], labels=labels),
        )
        if service_point is not None:
            sp = np.asarray(service_point, dtype=np.float64).reshape(1, 3)
            log(
                ent.SERVICE_POINT,
                rr.Points3D.from_fields(
                    positions=sp, colors=[(155, 89, 182)], labels=["service point"]
                ),
            )
        if search_path is not None and len(search_path) > 1:
            strip = rr.LineStrips3D(
                [np.asarray(search_path, dtype=np.float64)],
                radii=rr.Radius.ui_points(1.0),
                colors=(155, 89, 182, 140),
            )
            log(ent.SEARCH_PATH, strip, static=True)
        g = np.asarray(goal, dtype=np.float64).reshape(1, 3)
        log(ent.GOAL, rr.Points3D(g, radii=15.0, colors=(241, 196, 15), labels="goal"), static=True)
        mesh = _mesh(INTRUDER_COLOR)
        for n, path in enumerate(paths[1:], start=1):
            if n in members:
                self._log_own_styles(path)  # a fleet's member, as the ownship
                plan = ent.member_plan_path(ids[n])
                # below the member's transform like its trail, and drawn in world coordinates
                log(plan, rr.CoordinateFrame(f"tf#/{ent.WORLD}"), static=True)
                log(plan, _line_style(PLAN_COLOR, rr.Radius.ui_points(2.0)), static=True)
            else:
                log(path, mesh, static=True)

    def _log_own_styles(self, path: str) -> None:
        """An ownship's (or fleet member's) model and trail style."""
        log, trail = self._stream.log, ent.trail_path(path)
        log(path, _mesh(OWNSHIP_COLOR), static=True)
        # The trail sits below the aircraft's transform in the entity tree (docs/recording)
        # but is drawn in world coordinates, so it opts out of that transform.
        log(trail, rr.CoordinateFrame(f"tf#/{ent.WORLD}"), static=True)
        log(trail, _line_style(OWNSHIP_COLOR, rr.Radius.ui_points(TRAIL_POINTS)), static=True)

    def ready(self) -> None:
        """Nothing to wait for in-process (see :meth:`RecorderProcess.ready`)."""

    def log_traffic(self, state: TrafficState) -> None:
        """One frame of all aircraft; cheap (a copy), the sending happens in batches."""
        if not self.enabled:
            return
        self._traffic.append(state, self._decision)
        self._mission.traffic_geo(state.t, self._decision, state.pos)
        self._maybe_flush(state.t)

    def log_users(
        self,
        t: float,
        users_xyz: np.ndarray,
        rate_bps: np.ndarray,
        qos_bps: float,
        uav_pos: np.ndarray,
    ) -> None:
        """The users (K, 3) where they are at ``t`` with their current rates (K,) bit/s.

        Colours users by rate against ``qos_bps`` (red below, green at or above, grey with no
        rate), draws a link from ``uav_pos`` (3,) (or each user's serving UAV, (K, 3): a fleet) to
        each user with a rate, the rate bars, their map
        points and the status text. Cheap (copies); sent in batches.
        """
        if not self.enabled:
            return
        self._mission.users(t, self._decision, users_xyz, rate_bps, qos_bps, uav_pos)
        self._maybe_flush(t)

    def log_phase(self, t: float, phase: str, why: str = "") -> None:
        """The mission phase (e.g. ``Phase.ON_STATION.value``); only changes are recorded, so
        calling it every sample is fine. ``why`` goes into the phase log."""
        if not self.enabled:
            return
        self._mission.phase(t, self._decision, phase, why)
        self._maybe_flush(t)

    def log_orbit(self, t: float, centre: np.ndarray | None, radius_m: float) -> None:
        """The loiter circle in force from ``t`` (centre (3,) m, at its height); ``None`` or a
        radius <= 0 removes it. Repeats of the same orbit are dropped."""
        if not self.enabled:
            return
        self._mission.orbit(t, self._decision, centre, radius_m)

    def log_service_point(self, t: float, xyz: np.ndarray) -> None:
        """A service point chosen at ``t``: it becomes ``world/service_point`` and joins the
        history under ``world/service_points`` labelled with its time."""
        if not self.enabled:
            return
        self._mission.service_point(t, self._decision, xyz)

    def log_tracks(
        self, t: float, ids: Sequence[object], pos: np.ndarray, sigma_m: np.ndarray
    ) -> None:
        """The planner's belief: track ``ids[i]`` at ``pos[i]`` with 1-sigma ``sigma_m[i]``,
        drawn under ``world/tracks/N`` as a sphere of radius 2 sigma. Tracks missing from a
        call disappear from then on."""
        if not self.enabled:
            return
        self._mission.tracks(t, self._decision, ids, pos, sigma_m)
        self._maybe_flush(t)

    def _maybe_flush(self, t: float) -> None:
        self._last_t = max(self._last_t, t)
        if self._last_flush_t == -math.inf:
            self._last_flush_t = t
        if t - self._last_flush_t >= self._flush_period_s:
            self._flush()
            self._last_flush_t = t

    def log_decision(self, k: int, t: float, decision: Decision, intruder_ids: list[str]) -> None:
        """Decision ``k`` at sim time ``t``: its search tree, planned path and explanation."""
        if not self.enabled:
            return
        self._decision = k
        stream = self._stream
        stream.set_time(ent.SIM_TIME, duration=t)
        stream.set_time(ent.DECISION, sequence=k)
        graph = tree_graph(decision)
        stream.log(
            ent.TREE,
            rr.GraphNodes(
                graph.node_ids,
                positions=graph.positions,
                labels=graph.labels,
                colors=graph.colors,
                radii=graph.radii,
            ),
            rr.GraphEdges(graph.edges, graph_type="directed"),
        )
        plan = np.asarray(decision.plan, dtype=np.float64).reshape(-1, 3)
        plan_label = _plan_label(decision, intruder_ids)
        stream.log(ent.PLAN, rr.LineStrips3D([plan] if len(plan) > 1 else [], labels=plan_label))
        stream.log(ent.EXPLANATION, rr.TextLog(f"#{k}: {decision.explanation}", level="INFO"))
        if decision.counterfactual:
            stream.log(ent.EXPLANATION, rr.TextLog(decision.counterfactual, level="DEBUG"))

    def log_member_decision(
        self, member_id: str, k: int, t: float, decision: Decision, intruder_ids: list[str]
    ) -> None:
        """Fleet member ``member_id``'s decision ``k`` at ``t`` (docs/fleet.md): its chosen
        plan at ``world/ownship-i/plan``, labelled as member 0's, and its explanation at
        ``xai/ownship-i/explanation``. The members decide at member 0's decisions, so ``k`` is
        member 0's decision number too; the timelines are set for these two only, member 0's
        :meth:`log_decision` sets them again."""
        if not self.enabled:
            return
        stream = self._stream
        stream.set_time(ent.SIM_TIME, duration=t)
        stream.set_time(ent.DECISION, sequence=k)
        plan = np.asarray(decision.plan, dtype=np.float64).reshape(-1, 3)
        label = _plan_label(decision, intruder_ids)
        strips = [plan] if len(plan) > 1 else []
        stream.log(ent.member_plan_path(member_id), rr.LineStrips3D(strips, labels=label))
        text = f"{member_id} #{k}: {decision.explanation}"
        stream.log(ent.member_explanation_path(member_id), rr.TextLog(text, level="INFO"))

    def log_sample(self, state: TrafficState, decision_ms: float = math.nan) -> None:
        """One sample of a run in one call: the traffic (:meth:`log_traffic`) and the metrics
        it gives (docs/recording: the sum rate at the ownship's position with the ``link`` of
        :meth:`log_setup`, NaN without one; the separation, capped at 10 km; the ownship's
        bank and airspeed) with the last decision's planning time."""
        if not self.enabled:
            return
        self.log_traffic(state)
        rate = math.nan
        if self._link is not None:
            rate = float(self._link[0].sum_rate_bps(state.pos[0], self._link[1]))
        self.log_metrics(
            state.t,
            sum_rate_bps=rate,
            min_separation_m=min(state.min_separation(), 1e4),
            bank_deg=math.degrees(float(state.att[0, 0])),
            airspeed_mps=float(state.airspeed[0]),
            decision_ms=decision_ms,
        )

    def log_metrics(self, t: float, **scalars: float) -> None:
        """Scalars at sim time ``t``, each to ``metrics/<name>``; inf/nan are kept as gaps."""
        if not self.enabled:
            return
        for name, value in scalars.items():
            v = float(value)
            self._metrics[name].append(
                (float(t), self._decision, v if math.isfinite(v) else math.nan)
            )

    def close(self) -> None:
        """Send what is buffered and finish the file; safe to call twice."""
        if self._closed:
            return
        self._closed = True
        if self.enabled:
            self._open_sinks(None)
            if math.isfinite(self._last_t):
                self._mission.end(self._last_t, self._decision)
            self._flush()
            try:
                self._stream.flush(timeout_sec=10.0)  # a vanished viewer must not hang the run
                self._stream.disconnect()
            except Exception as exc:  # noqa: BLE001 - the viewer went away; the file is whole
                log.warning("rerun viewer: %s; the recording file is complete", exc)

    def __enter__(self) -> RunRecorder:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()

    # ---- batching -------------------------------------------------------------------------

    def _flush(self) -> None:
        self._traffic.flush()
        self._mission.flush()
        for name, rows in self._metrics.items():
            if not rows:
                continue
            t, k, v = zip(*rows, strict=True)
            self._stream.send_columns(
                ent.metric_path(name),
                indexes=[
                    rr.TimeColumn(ent.SIM_TIME, duration=np.asarray(t)),
                    rr.TimeColumn(ent.DECISION, sequence=np.asarray(k, dtype=np.int64)),
                ],
                columns=rr.Scalars.columns(scalars=np.asarray(v)),
            )
            rows.clear()


def _mesh(color: tuple[int, int, int]) -> rr.Mesh3D:
    vertices, normals, triangles = aircraft_mesh()
    return rr.Mesh3D(
        vertex_positions=vertices,
        vertex_normals=normals,
        triangle_indices=triangles,
        albedo_factor=color,
        face_rendering="DoubleSided",  # wings are single sheets, seen from above and below
    )


def _line_style(color: tuple[int, ...], radius) -> rr.LineStrips3D:
    return rr.LineStrips3D.from_fields(colors=[color], radii=[radius])


def _plan_label(decision: Decision, intruder_ids: list[str]) -> str:
    """Short, as it floats in the scene: the smallest separation predicted along the drawn
    plan (the chosen action's best line) and the intruder it is from, both from that line."""
    chosen = next((c for c in decision.children if c.action == decision.action), None)
    sep = chosen.predicted_min_separation_m if chosen is not None else math.inf
    if not math.isfinite(sep):
        return "plan"
    closest = _closest_on_plan(decision, intruder_ids)
    return f"plan: {sep:.0f} m from {closest}" if closest else f"plan: {sep:.0f} m clear"


def _closest_on_plan(decision: Decision, intruder_ids: list[str]) -> str | None:
    """Name of the intruder that comes closest along the chosen action's line."""
    chosen = next((c for c in decision.children if c.action == decision.action), None)
    if chosen is None or chosen.closest_intruder is None:
        return None
    who = chosen.closest_intruder
    # The planner may give an index into the intruder list or the id itself.
    if isinstance(who, (int, np.integer)) and 0 <= who < len(intruder_ids):
        return intruder_ids[int(who)]
    return str(who)


class RecorderProcess:
    """A :class:`RunRecorder` in its own process, with the same ``log_*`` methods (sent
    without waiting, in order): ``uavxai run`` records off the simulation's core, whose
    time goes to JSBSim. The recording is the same; ``close()`` returns when it is written
    (and raises what failed there)."""

    def __init__(self, *args: object, **kwargs: object) -> None:
        from uavxai.worker import Worker

        self._worker = Worker(RunRecorder, *args, name="rerun recorder", **kwargs)

    def __getattr__(self, name: str):
        if name.startswith("log_"):
            return functools.partial(self._worker.post, name)
        raise AttributeError(name)

    def ready(self) -> None:
        """Wait until the process has started and done what was asked so far."""
        self._worker.call("")

    def close(self) -> None:
        self._worker.close("close")
