"""Aircraft poses and trails, buffered per frame and sent to rerun as columns.

One ``rr.log`` per aircraft per frame costs tens of microseconds each; a 400 s run at 10 Hz
with 21 aircraft would spend seconds in logging alone. Here a frame is only copied into a list,
and ``flush`` sends each aircraft's whole buffer in one ``send_columns`` call.

Trails are short segments (``trail_block`` frames each, joined end to start), logged at the
time of their last point; the blueprint shows all segments up to the time cursor, so the
viewer draws a growing trail without any frame re-sending the whole history.
"""

from __future__ import annotations

import numpy as np
import pyarrow as pa
import rerun as rr

from uavxai.dynamics.state import OWNSHIP_ID, TrafficState, is_member
from uavxai.recording import entities as ent
from uavxai.recording.aircraft_model import attitude_quaternions

TRAIL_BLOCK = 5  # frames per trail segment: 0.5 s at 10 Hz, shorter than the model is long


def aircraft_paths(ids: tuple[str, ...]) -> list[str]:
    """Entity path of each row of a TrafficState: row 0 the ownship (a fleet's member 0 too),
    a fleet's other members ``world/ownship-i``, the intruders ``world/intruders/N``."""
    return [
        ent.OWNSHIP if n == 0 or i == OWNSHIP_ID
        else ent.member_path(i) if is_member(i) else ent.intruder_path(i, n)
        for n, i in enumerate(ids)
    ]  # fmt: skip


def member_rows(ids: tuple[str, ...]) -> list[int]:
    """The rows of a fleet's members other than row 0 (none with one ownship)."""
    return [n for n, i in enumerate(ids) if n > 0 and is_member(i)]


class TrafficLog:
    def __init__(self, stream: rr.RecordingStream, trail_block: int = TRAIL_BLOCK) -> None:
        self._stream = stream
        self._trail_block = trail_block
        self._ids: tuple[str, ...] | None = None
        self._paths: list[str] = []
        self._members: list[int] = []  # a fleet's members' rows (not row 0): trails of their own
        self._intruders: list[int] = []
        self._t: list[float] = []
        self._k: list[int] = []
        self._pos: list[np.ndarray] = []
        self._att: list[np.ndarray] = []
        self._trail_end: np.ndarray | None = None  # last point of the last segment, (N, 3)
        self._frames_sent = 0

    def __len__(self) -> int:
        return len(self._t)

    def append(self, state: TrafficState, decision: int) -> None:
        if state.ids != self._ids:
            # A different set of aircraft: close off the old one's columns before remapping.
            self.flush()
            self._ids = tuple(state.ids)
            self._paths = aircraft_paths(self._ids)
            self._members = member_rows(self._ids)
            self._intruders = [n for n in range(1, len(self._ids)) if n not in self._members]
            self._trail_end = None
        self._t.append(float(state.t))
        self._k.append(int(decision))
        # Copies: the dynamics may reuse its arrays for the next step.
        self._pos.append(np.array(state.pos, dtype=np.float64))
        self._att.append(np.array(state.att, dtype=np.float64))

    def flush(self) -> None:
        if not self._t:
            return
        t = np.asarray(self._t)
        k = np.asarray(self._k, dtype=np.int64)
        pos = np.stack(self._pos)  # (T, N, 3)
        quat = attitude_quaternions(np.stack(self._att).reshape(-1, 3)).reshape(*pos.shape[:2], 4)
        index = [rr.TimeColumn(ent.SIM_TIME, duration=t), rr.TimeColumn(ent.DECISION, sequence=k)]
        for j, path in enumerate(self._paths):
            columns = rr.Transform3D.columns(translation=pos[:, j], quaternion=quat[:, j])
            self._stream.send_columns(path, indexes=index, columns=columns)
        self._send_trails(t, k, pos)
        self._frames_sent += len(t)
        self._t, self._k, self._pos, self._att = [], [], [], []

    def _send_trails(self, t: np.ndarray, k: np.ndarray, pos: np.ndarray) -> None:
        frame_no = self._frames_sent + np.arange(1, len(t) + 1)
        ends = np.flatnonzero(frame_no % self._trail_block == 0)
        if not ends.size or ends[-1] != len(t) - 1:
            ends = np.append(ends, len(t) - 1)  # the trail reaches the aircraft at each flush
        # Prepend the last point already drawn so each segment starts where the previous ended.
        carried = self._trail_end is not None
        ext = np.concatenate([self._trail_end[None], pos]) if carried else pos
        stops = ends + int(carried)
        starts = np.concatenate([[0], stops[:-1]])
        own, others, own_len, other_len = [], [], [], []
        members = self._members
        fleet: list[list[np.ndarray]] = [[] for _ in members]
        for a, b in zip(starts, stops, strict=True):
            seg = ext[a : b + 1]  # (L, N, 3)
            own.append(seg[:, 0])
            for strips, row in zip(fleet, members, strict=True):
                strips.append(seg[:, row])
            others.append(seg[:, self._intruders].transpose(1, 0, 2).reshape(-1, 3))
            own_len.append(len(seg))
            other_len.extend([len(seg)] * len(self._intruders))
        self._trail_end = pos[-1]
        index = [
            rr.TimeColumn(ent.SIM_TIME, duration=t[ends]),
            rr.TimeColumn(ent.DECISION, sequence=k[ends]),
        ]
        strips = rr.LineStrips3D.columns(strips=_strips_array(np.concatenate(own), own_len))
        self._stream.send_columns(ent.OWNSHIP_TRAIL, indexes=index, columns=strips)
        for row, member in zip(members, fleet, strict=True):
            strips = rr.LineStrips3D.columns(strips=_strips_array(np.concatenate(member), own_len))
            path = ent.trail_path(self._paths[row])
            self._stream.send_columns(path, indexes=index, columns=strips)
        n_intruders = len(self._intruders)
        if n_intruders:
            arr = _strips_array(np.concatenate(others), other_len)
            strips = rr.LineStrips3D.columns(strips=arr).partition([n_intruders] * len(ends))
            self._stream.send_columns(ent.INTRUDER_TRAILS, indexes=index, columns=strips)


_STRIP_TYPE = rr.components.LineStrip3DBatch._ARROW_DATATYPE


def _strips_array(points: np.ndarray, lengths: list[int]) -> pa.ListArray:
    """Line strips as one Arrow array: rerun's own converter goes strip by strip, ~20x slower."""
    offsets = np.concatenate([[0], np.cumsum(lengths)]).astype(np.int32)
    flat = pa.array(points.astype(np.float32, copy=False).ravel())
    inner = pa.FixedSizeListArray.from_arrays(flat, type=_STRIP_TYPE.value_type)
    return pa.ListArray.from_arrays(pa.array(offsets), inner, type=_STRIP_TYPE)
