"""The mission in the recording: users and their service, links, rate bars, the orbit, service
points, the phase, the planner's tracks, and a map (docs/recording/README.md).

The engine calls at the sample rate (10 Hz); like :mod:`uavxai.recording.traffic_log`, a call
only copies its arrays into a buffer and :meth:`MissionLog.flush` sends each entity's rows in
one ``send_columns``. Rare events (phase changes, a new orbit or service point) are buffered
the same way so every row carries both timelines.

Colours say one thing everywhere (3-D users, links, bars, map): red to orange below the QoS
rate (brighter the closer to it), green at or above it (darker the more margin), grey when a
user gets nothing at all.
"""

from __future__ import annotations

import functools
import math
from collections.abc import Sequence
from dataclasses import dataclass, field

import numpy as np
import pyarrow as pa
import rerun as rr
from rerun.components import TensorDataBatch

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.errors import UserError
from uavxai.recording import entities as ent
from uavxai.recording.traffic_log import _strips_array

# Colours (RGB) of the QoS scale and of the things drawn beside it.
UNSERVED_COLOR = np.array([140, 140, 140])
BELOW_LOW = np.array([214, 39, 40])  # far below QoS
BELOW_HIGH = np.array([255, 165, 0])  # just below QoS
ABOVE_LOW = np.array([130, 220, 90])  # just at QoS
ABOVE_HIGH = np.array([20, 130, 50])  # 4x QoS and more
TRACK_COLOR = (0, 190, 255, 110)  # belief: translucent cyan, unlike the red intruders
ORBIT_COLOR = (46, 204, 113)
SERVICE_POINT_COLOR = (155, 89, 182)
OWNSHIP_MAP_COLOR = (255, 165, 0)
INTRUDER_MAP_COLOR = (220, 60, 60)
PHASE_COLORS = {
    "transit": (52, 152, 219),
    "on_station": (46, 204, 113),
    "avoiding": (231, 76, 60),
    "returning": (155, 89, 182),
}
QOS_BAND_COLOR = (255, 255, 255, 45)
ABOVE_SPAN = 4.0  # rate/QoS at which the green stops darkening
ORBIT_SEGMENTS = 72
MIN_TRACK_RADIUS = rr.Radius.ui_points(4.0)  # a track with no uncertainty stays visible


def qos_colors(rate_bps: np.ndarray, qos_bps: float) -> np.ndarray:
    """RGBA (uint8) per rate: the QoS scale above. ``qos_bps <= 0``: every served user is green."""
    rate = np.asarray(rate_bps, dtype=np.float64)
    out = np.empty((*rate.shape, 4), dtype=np.uint8)
    out[..., 3] = 255
    ratio = rate / qos_bps if qos_bps > 0 else np.where(rate > 0, ABOVE_SPAN, 0.0)
    below = ratio < 1.0
    f_below = np.clip(ratio, 0.0, 1.0)[..., None]
    # log scale above: 2x QoS is as far along as 2x from 2x to 4x
    f_above = np.clip(np.log(np.maximum(ratio, 1.0)) / math.log(ABOVE_SPAN), 0.0, 1.0)[..., None]
    rgb = np.where(
        below[..., None],
        BELOW_LOW + f_below * (BELOW_HIGH - BELOW_LOW),
        ABOVE_LOW + f_above * (ABOVE_HIGH - ABOVE_LOW),
    )
    rgb = np.where((rate <= 0.0)[..., None], UNSERVED_COLOR, rgb)
    out[..., :3] = np.rint(rgb).astype(np.uint8)
    return out


def format_rate(bps: float) -> str:
    if not math.isfinite(bps):
        return "-"
    if bps >= 1e6:
        return f"{bps / 1e6:.1f} Mbit/s"
    return f"{bps / 1e3:.0f} kbit/s"


@functools.lru_cache(maxsize=1 << 16)
def _user_label(n: int, shown_bps: int) -> str:
    # Cached on the rate as printed: formatting 20 labels per sample was most of the flush.
    return f"user {n}: {format_rate(shown_bps)}"


def _shown_rate(rate_bps: np.ndarray) -> np.ndarray:
    """Each rate rounded to what ``format_rate`` prints (0.1 Mbit/s or 1 kbit/s), in bit/s."""
    mega = np.rint(rate_bps / 1e5) * 1e5
    return np.where(mega >= 1e6, mega, np.rint(rate_bps / 1e3) * 1e3).astype(np.int64)


def tracks_of(intruders: Sequence) -> tuple[list, np.ndarray, np.ndarray]:
    """``(ids, pos (N, 3), sigma_m (N,))`` of a planner's picture (``avoidance.types.Intruder``
    list), the arguments of ``RunRecorder.log_tracks``."""
    ids = [i.id for i in intruders]
    pos = np.array([(i.x, i.y, i.h) for i in intruders], dtype=np.float64).reshape(-1, 3)
    sigma = np.array([i.sigma_m for i in intruders], dtype=np.float64)
    return ids, pos, sigma


def phase_title(phase: str) -> str:
    return phase.replace("_", " ")


@dataclass
class _Rows:
    """Buffered rows of one entity: times, decision index and per-row payloads."""

    t: list[float] = field(default_factory=list)
    k: list[int] = field(default_factory=list)
    items: list = field(default_factory=list)

    def add(self, t: float, k: int, item) -> None:
        self.t.append(float(t))
        self.k.append(int(k))
        self.items.append(item)

    def index(self) -> list[rr.TimeColumn]:
        return [
            rr.TimeColumn(ent.SIM_TIME, duration=np.asarray(self.t)),
            rr.TimeColumn(ent.DECISION, sequence=np.asarray(self.k, dtype=np.int64)),
        ]

    def clear(self) -> None:
        self.t, self.k, self.items = [], [], []


class MissionLog:
    """Buffers the mission's per-sample data; ``flush`` sends it. ``frame`` enables the map."""

    def __init__(self, stream: rr.RecordingStream) -> None:
        self._stream = stream
        self.frame: LocalFrame | None = None
        self._users = _Rows()  # (xyz (K,3), rate (K,), qos, uav (3,))
        self._traffic_geo = _Rows()  # positions (N,3), row 0 the ownship
        self._phase_rows = _Rows()  # phase number (float)
        self._phase_text = _Rows()  # (text, colour)
        self._status = _Rows()  # markdown
        self._orbit = _Rows()  # (centre, radius) or None
        self._service_points: list[tuple[float, np.ndarray]] = []
        self._sp_rows = _Rows()  # index into _service_points (inclusive end)
        self._tracks: dict[str, _Rows] = {}  # path -> rows of (xyz, radius, label) or None
        self._tracks_live: set[str] = set()
        self._phase: str | None = None
        self._phase_since = 0.0
        self._phase_numbers = {p: float(i) for i, p in enumerate(ent.PHASES)}
        self._last_orbit: tuple[tuple[float, ...], float] | None = None
        self._service_line = ""  # the users' part of the status text, kept for phase changes

    # ---- static styles --------------------------------------------------------------------

    def log_styles(self) -> None:
        log = self._stream.log
        log(ent.LINKS, rr.LineStrips3D.from_fields(radii=[rr.Radius.ui_points(1.0)]), static=True)
        log(
            ent.ORBIT,
            # label on hover: it would sit on the plan's label at the orbit's centre
            rr.LineStrips3D.from_fields(
                colors=[ORBIT_COLOR], radii=[rr.Radius.ui_points(1.5)], show_labels=False
            ),
            static=True,
        )
        log(
            ent.SERVICE_POINTS,
            rr.Points3D.from_fields(radii=[rr.Radius.ui_points(6.0)], show_labels=True),
            static=True,
        )
        names = ", ".join(f"{i} {phase_title(p)}" for i, p in enumerate(ent.PHASES))
        # A phase holds until the next change: steps, not ramps, and every change drawn
        # (averaging points that share a pixel would blur a short phase away).
        series = rr.SeriesLines(
            names=names, widths=2.0, interpolation_mode="StepAfter", aggregation_policy="Off"
        )
        log(ent.PHASE_METRIC, series, static=True)
        log(
            ent.MAP_OWNSHIP,
            rr.GeoPoints.from_fields(colors=[OWNSHIP_MAP_COLOR], radii=[rr.Radius.ui_points(9.0)]),
            static=True,
        )
        log(
            ent.MAP_INTRUDERS,
            rr.GeoPoints.from_fields(colors=[INTRUDER_MAP_COLOR], radii=[rr.Radius.ui_points(4.0)]),
            static=True,
        )
        # users smaller than aircraft: a user just below QoS is orange like the ownship
        log(ent.MAP_USERS, rr.GeoPoints.from_fields(radii=[rr.Radius.ui_points(3.0)]), static=True)
        log(
            ent.MAP_ORBIT,
            rr.GeoLineStrings.from_fields(colors=[ORBIT_COLOR], radii=[rr.Radius.ui_points(1.5)]),
            static=True,
        )
        log(
            ent.MAP_SERVICE_POINTS,
            rr.GeoPoints.from_fields(
                colors=[SERVICE_POINT_COLOR], radii=[rr.Radius.ui_points(5.0)]
            ),
            static=True,
        )

    # ---- the calls ------------------------------------------------------------------------

    def users(
        self,
        t: float,
        k: int,
        users_xyz: np.ndarray,
        rate_bps: np.ndarray,
        qos_bps: float,
        uav_pos: np.ndarray,
    ) -> None:
        users = np.array(users_xyz, dtype=np.float64)  # a copy: callers reuse their arrays
        rate = np.array(rate_bps, dtype=np.float64)
        uav = np.array(uav_pos, dtype=np.float64)
        if users.ndim != 2 or users.shape[1] != 3:
            raise UserError(f"log_users: users_xyz must be (K, 3) metres, got {users.shape}")
        if rate.shape != (len(users),):
            raise UserError(
                f"log_users: rate_bps must be one rate per user ({len(users)},), got {rate.shape}"
            )
        if not np.all(np.isfinite(rate)) or np.any(rate < 0):
            raise UserError("log_users: rate_bps must be finite rates >= 0 bit/s")
        if uav.shape == (3,):
            uav = np.broadcast_to(uav, users.shape)  # one UAV serves them all
        elif uav.shape != users.shape:
            raise UserError(
                f"log_users: uav_pos must be (3,) metres or each user's serving UAV "
                f"({len(users)}, 3), got {uav.shape}"
            )
        qos = float(qos_bps)
        if not math.isfinite(qos) or qos < 0:
            raise UserError(f"log_users: qos_bps must be a finite rate >= 0 bit/s, got {qos_bps}")
        self._users.add(t, k, (users, rate, qos, uav))
        self._status_for_users(t, k, rate, qos)

    def traffic_geo(self, t: float, k: int, pos: np.ndarray) -> None:
        if self.frame is not None:
            self._traffic_geo.add(t, k, np.array(pos, dtype=np.float64))

    def phase(self, t: float, k: int, phase: str, why: str = "") -> None:
        """Rows only on a change (callers may call every sample); the plot steps at ``t``."""
        phase = str(phase)
        if phase == self._phase:
            return
        if phase not in self._phase_numbers:
            self._phase_numbers[phase] = float(len(self._phase_numbers))
        self._phase_rows.add(t, k, self._phase_numbers[phase])
        title = phase_title(phase)
        text = f"phase: {title}" + (f" ({why})" if why else "")
        self._phase_text.add(t, k, (text, PHASE_COLORS.get(phase, (200, 200, 200))))
        self._phase, self._phase_since = phase, float(t)
        self._status.add(t, k, self._status_text(t))

    def end(self, t: float, k: int) -> None:
        """The run ends at ``t``: draw the last phase up to there (a step plot stops at its
        last point)."""
        if self._phase is not None and t > self._phase_since:
            self._phase_rows.add(t, k, self._phase_numbers[self._phase])

    def orbit(self, t: float, k: int, centre: np.ndarray | None, radius_m: float) -> None:
        if centre is None or not radius_m > 0:
            key = None
        else:
            c = np.asarray(centre, dtype=np.float64).reshape(3)
            key = (tuple(round(float(v), 3) for v in c), round(float(radius_m), 3))
        if key == self._last_orbit:
            return
        self._last_orbit = key
        self._orbit.add(t, k, key)

    def service_point(self, t: float, k: int, xyz: np.ndarray) -> None:
        p = np.array(xyz, dtype=np.float64).reshape(3)
        self._service_points.append((float(t), p))
        self._sp_rows.add(t, k, len(self._service_points))

    def tracks(
        self, t: float, k: int, ids: Sequence[object], pos: np.ndarray, sigma_m: np.ndarray
    ) -> None:
        pos = np.asarray(pos, dtype=np.float64).reshape(-1, 3)
        sigma = np.asarray(sigma_m, dtype=np.float64).reshape(-1)
        if not (len(ids) == len(pos) == len(sigma)):
            raise UserError(
                f"log_tracks: ids ({len(ids)}), pos ({len(pos)}) and sigma_m ({len(sigma)}) "
                "must have one entry per track"
            )
        if np.any(~np.isfinite(sigma)) or np.any(sigma < 0):
            raise UserError("log_tracks: sigma_m must be finite and >= 0 m")
        seen = set()
        for i, track_id in enumerate(ids):
            path = ent.track_path(track_id)
            seen.add(path)
            two_sigma = 2.0 * float(sigma[i])
            # radius in scene metres; a (near) exact track gets a small on-screen dot instead
            radius = two_sigma if two_sigma >= 1.0 else MIN_TRACK_RADIUS
            if path not in self._tracks:
                self._tracks[path] = _Rows()
                self._stream.log(path, rr.Points3D.from_fields(colors=[TRACK_COLOR]), static=True)
            label = _track_label(path.rsplit("/", 1)[1], round(two_sigma))
            self._tracks[path].add(t, k, (pos[i].copy(), radius, label))
        for path in self._tracks_live - seen:  # dropped tracks vanish from the scene
            self._tracks[path].add(t, k, None)
        self._tracks_live = seen

    # ---- sending --------------------------------------------------------------------------

    def flush(self) -> None:
        self._flush_users()
        self._flush_traffic_geo()
        self._flush_phase()
        self._flush_orbit()
        self._flush_service_points()
        self._flush_tracks()
        if self._status.t:
            self._send(
                ent.STATUS,
                self._status,
                rr.TextDocument.columns(
                    text=self._status.items, media_type=["text/markdown"] * len(self._status.t)
                ),
            )

    def _send(self, path: str, rows: _Rows, columns) -> None:
        self._stream.send_columns(path, indexes=rows.index(), columns=columns)
        rows.clear()

    def _flush_users(self) -> None:
        rows = self._users
        if not rows.t:
            return
        lengths = [len(u) for u, *_ in rows.items]
        users = np.concatenate([u for u, *_ in rows.items])
        rates = np.concatenate([r for _, r, *_ in rows.items])
        qos = np.repeat([q for *_, q, _ in rows.items], lengths)
        colors = _colors_per_row(rates, qos)
        user_no = np.concatenate([np.arange(1, n + 1) for n in lengths])
        shown = _shown_rate(rates)
        labels = list(map(_user_label, user_no.tolist(), shown.tolist()))
        index = rows.index()
        points = rr.Points3D.columns(positions=users, colors=colors, labels=labels)
        self._stream.send_columns(ent.USERS, indexes=index, columns=points.partition(lengths))

        # links: from the UAV to each user that gets a rate, fainter the weaker the link
        served = rates > 0.0
        uav = np.concatenate([u for *_, u in rows.items])  # each user's serving UAV
        ends = np.stack([uav[served], users[served]], axis=1).reshape(-1, 3)
        ratio = np.where(qos > 0, rates / np.where(qos > 0, qos, 1.0), ABOVE_SPAN)[served]
        link_colors = colors[served].copy()
        link_colors[:, 3] = (70 + 185 * np.clip(ratio / 2.0, 0.0, 1.0)).astype(np.uint8)
        row_of = np.repeat(np.arange(len(lengths)), lengths)
        n_served = np.bincount(row_of[served], minlength=len(lengths))
        strips = rr.LineStrips3D.columns(
            strips=_strips_array(ends, [2] * int(served.sum())), colors=link_colors
        )
        self._stream.send_columns(
            ent.LINKS, indexes=index, columns=strips.partition([int(n) for n in n_served])
        )

        # bars: two charts over the same user axis, so each bar takes its side's colour
        k_max = max(lengths)
        table = np.zeros((len(lengths), k_max))
        qos_rows = np.zeros((len(lengths), k_max))
        for j, (_, r, q, _) in enumerate(rows.items):
            table[j, : len(r)] = r
            qos_rows[j, :] = q
        at = table >= qos_rows
        # (the colour goes with the rows: BarChart.from_fields for a static style warns in 0.41)
        users_axis = np.arange(1, k_max + 1, dtype=np.float64)  # bar i is "user i" as labelled
        for path, mask, color in (
            (ent.RATES_AT_QOS, at, ABOVE_HIGH),
            (ent.RATES_BELOW_QOS, ~at, BELOW_LOW),
        ):
            mbps = np.where(mask, table, 0.0) / 1e6
            bar_colors = np.tile(np.append(color, 255).astype(np.uint8), (len(mbps), 1))
            columns = rr.BarChart.columns(
                values=_bar_values(mbps),
                color=bar_colors,
                abscissa=_bar_values(np.tile(users_axis, (len(mbps), 1))),
            )
            self._stream.send_columns(path, indexes=index, columns=columns)
        # the QoS rate as a faint band over each bar: a red bar shows its gap to it
        qos_band = rr.BarChart.columns(
            values=_bar_values(qos_rows / 1e6),
            color=np.tile(np.array(QOS_BAND_COLOR, dtype=np.uint8), (len(lengths), 1)),
            abscissa=_bar_values(np.tile(users_axis, (len(lengths), 1))),
        )
        self._stream.send_columns(ent.RATES_QOS, indexes=index, columns=qos_band)

        if self.frame is not None:
            lat, lon, _ = self.frame.to_geodetic(users[:, 0], users[:, 1], users[:, 2])
            geo = rr.GeoPoints.columns(positions=np.column_stack([lat, lon]), colors=colors)
            self._stream.send_columns(ent.MAP_USERS, indexes=index, columns=geo.partition(lengths))
        rows.clear()

    def _status_for_users(self, t: float, k: int, rate: np.ndarray, qos: float) -> None:
        n_ok = int((rate >= qos).sum())
        weakest = int(np.argmin(rate)) if len(rate) else -1
        line = f"**{n_ok} of {len(rate)}** users at QoS ≥ {format_rate(qos)}"
        line += f", sum **{format_rate(float(rate.sum()))}**"
        if weakest >= 0:
            line += f"; weakest user {weakest + 1}: {format_rate(float(rate[weakest]))}"
        self._service_line = line
        self._status.add(t, k, self._status_text(t))

    def _status_text(self, t: float) -> str:
        # Two short lines: the view is small and cuts off what does not fit.
        phase = phase_title(self._phase).upper() if self._phase else "NO PHASE YET"
        head = f"**{phase}** for {t - self._phase_since:.0f} s (t = {t:.0f} s)"
        return head + (f"  \n{self._service_line}" if self._service_line else "")

    def _flush_traffic_geo(self) -> None:
        rows = self._traffic_geo
        if not rows.t or self.frame is None:
            rows.clear()
            return
        lengths = [len(p) for p in rows.items]
        pos = np.concatenate(rows.items)
        lat, lon, _ = self.frame.to_geodetic(pos[:, 0], pos[:, 1], pos[:, 2])
        latlon = np.column_stack([lat, lon])
        first = np.cumsum([0, *lengths[:-1]])
        is_own = np.zeros(len(pos), dtype=bool)
        is_own[first] = True
        index = rows.index()
        own = rr.GeoPoints.columns(positions=latlon[is_own])
        self._stream.send_columns(ent.MAP_OWNSHIP, indexes=index, columns=own)
        others = rr.GeoPoints.columns(positions=latlon[~is_own])
        self._stream.send_columns(
            ent.MAP_INTRUDERS, indexes=index, columns=others.partition([n - 1 for n in lengths])
        )
        rows.clear()

    def _flush_phase(self) -> None:
        if self._phase_rows.t:
            values = np.asarray(self._phase_rows.items, dtype=np.float64)
            self._send(ent.PHASE_METRIC, self._phase_rows, rr.Scalars.columns(scalars=values))
        if self._phase_text.t:
            texts = [text for text, _ in self._phase_text.items]
            colors = [color for _, color in self._phase_text.items]
            columns = rr.TextLog.columns(text=texts, level=["INFO"] * len(texts), color=colors)
            self._send(ent.PHASE, self._phase_text, columns)

    def _flush_orbit(self) -> None:
        rows = self._orbit
        if not rows.t:
            return
        circles, labels, lengths = [], [], []
        for key in rows.items:
            if key is None:
                lengths.append(0)
                continue
            (cx, cy, ch), radius = key
            a = np.linspace(0.0, 2 * math.pi, ORBIT_SEGMENTS + 1)
            circle = np.column_stack(
                [cx + radius * np.sin(a), cy + radius * np.cos(a), np.full_like(a, ch)]
            )
            circles.append(circle)
            labels.append(f"orbit r = {radius:.0f} m")
            lengths.append(1)
        pts = np.concatenate(circles) if circles else np.zeros((0, 3))
        strips = _strips_array(pts, [len(c) for c in circles])
        index = rows.index()
        columns = rr.LineStrips3D.columns(strips=strips, labels=labels).partition(lengths)
        self._stream.send_columns(ent.ORBIT, indexes=index, columns=columns)
        if self.frame is not None:
            geo = []
            for c in circles:
                lat, lon, _ = self.frame.to_geodetic(c[:, 0], c[:, 1], c[:, 2])
                geo.append(np.column_stack([lat, lon]))
            lines = rr.GeoLineStrings.columns(line_strings=geo).partition(lengths)
            self._stream.send_columns(ent.MAP_ORBIT, indexes=index, columns=lines)
        rows.clear()

    def _flush_service_points(self) -> None:
        rows = self._sp_rows
        if not rows.t:
            return
        # Each row holds the whole history so far: a handful of points, chosen rarely.
        pos = [self._service_points[i][1] for n in rows.items for i in range(n)]
        labels = [f"t = {self._service_points[i][0]:.0f} s" for n in rows.items for i in range(n)]
        colors = []
        for n in rows.items:
            colors.extend([(*SERVICE_POINT_COLOR, 110)] * (n - 1) + [(*SERVICE_POINT_COLOR, 255)])
        index = rows.index()
        columns = rr.Points3D.columns(positions=np.stack(pos), labels=labels, colors=colors)
        self._stream.send_columns(
            ent.SERVICE_POINTS, indexes=index, columns=columns.partition(rows.items)
        )
        # the current one at the path docs/recording/README.md names too
        current = np.stack([self._service_points[n - 1][1] for n in rows.items])
        self._stream.send_columns(
            ent.SERVICE_POINT, indexes=index, columns=rr.Points3D.columns(positions=current)
        )
        if self.frame is not None:
            p = np.stack(pos)
            lat, lon, _ = self.frame.to_geodetic(p[:, 0], p[:, 1], p[:, 2])
            geo = rr.GeoPoints.columns(positions=np.column_stack([lat, lon]))
            self._stream.send_columns(
                ent.MAP_SERVICE_POINTS, indexes=index, columns=geo.partition(rows.items)
            )
        rows.clear()

    def _flush_tracks(self) -> None:
        for path, rows in self._tracks.items():
            if not rows.t:
                continue
            present = [item for item in rows.items if item is not None]
            lengths = [0 if item is None else 1 for item in rows.items]
            pos = np.stack([p for p, _, _ in present]) if present else np.zeros((0, 3))
            columns = rr.Points3D.columns(
                positions=pos,
                radii=np.asarray([r for _, r, _ in present], dtype=np.float32),
                labels=[lbl for _, _, lbl in present],
            )
            self._send(path, rows, columns.partition(lengths))


@functools.lru_cache(maxsize=1 << 14)
def _track_label(name: str, two_sigma_m: int) -> str:
    return f"track {name} ±{two_sigma_m} m"


def _colors_per_row(rates: np.ndarray, qos: np.ndarray) -> np.ndarray:
    """``qos_colors`` with a QoS per element (rows may carry different QoS rates)."""
    out = np.empty((len(rates), 4), dtype=np.uint8)
    for q in np.unique(qos):
        sel = qos == q
        out[sel] = qos_colors(rates[sel], float(q))
    return out


_TENSOR_TYPE = TensorDataBatch._ARROW_DATATYPE
_UNION = _TENSOR_TYPE.field("buffer").type
_F64_CODE = _UNION.type_codes[[m.name for m in _UNION].index("F64")]


def _bar_values(values: np.ndarray) -> pa.StructArray:
    """Rows of a ``(T, K)`` array as T bar-chart tensors in one Arrow array: rerun's converter
    takes one tensor per call (about 30 us each)."""
    v = np.ascontiguousarray(values, dtype=np.float64)
    n, k = v.shape
    row_offsets = pa.array(np.arange(n + 1, dtype=np.int32))
    shape = pa.ListArray.from_arrays(
        row_offsets, pa.array(np.full(n, k, dtype=np.uint64)), type=_TENSOR_TYPE.field("shape").type
    )
    names = pa.nulls(n, type=_TENSOR_TYPE.field("names").type)
    children = []
    for member in _UNION:
        if member.name == "F64":
            offsets = pa.array(np.arange(n + 1, dtype=np.int32) * k)
            children.append(
                pa.ListArray.from_arrays(offsets, pa.array(v.ravel()), type=member.type)
            )
        else:
            children.append(pa.array([], type=member.type))
    # from_buffers keeps the union members' non-null flags, which UnionArray.from_dense drops
    buffer = pa.Array.from_buffers(
        _UNION,
        n,
        [
            None,
            pa.py_buffer(np.full(n, _F64_CODE, dtype=np.int8).tobytes()),
            pa.py_buffer(np.arange(n, dtype=np.int32).tobytes()),
        ],
        children=children,
    )
    return pa.StructArray.from_arrays([shape, names, buffer], fields=list(_TENSOR_TYPE))
