"""A telemetry log (.tlog) of the bridge's traffic, in the format MAVProxy writes and reads.

Each frame is stored as an 8-byte big-endian unsigned timestamp (microseconds since the Unix
epoch) followed by the frame's raw bytes, so `pymavlink.mavutil.mavlink_connection(path)`,
MAVProxy, MAVExplorer and QGroundControl's log replay can open a run's link traffic. The
timestamps are simulated time placed after ``t0_unix_s`` (when the run started), so a replay
shows the episode at its own pace, not at the pace the computer flew it.
"""

from __future__ import annotations

import struct
from pathlib import Path
from types import TracebackType

from uavxai.errors import UserError

_STAMP = struct.Struct(">Q")


class TlogWriter:
    """Appends frames to a new .tlog file; refuses to overwrite an existing one (a run's log
    is evidence; losing it to the next run by accident is worse than a clear error)."""

    def __init__(self, path: str | Path, t0_unix_s: float) -> None:
        self.path = Path(path)
        self._t0_us = round(t0_unix_s * 1e6)
        try:
            # "xb": created here or not at all, atomically (no check-then-open race).
            self._file = open(self.path, "xb")  # noqa: SIM115 - closed by close()
        except FileExistsError as err:
            raise UserError(
                f"the telemetry log {self.path} already exists; remove it or choose another file"
            ) from err
        except OSError as err:
            raise UserError(f"cannot create the telemetry log {self.path}: {err}") from err
        self.frames = 0

    def write(self, t_sim_s: float, frame: bytes) -> None:
        """Log one frame at simulated time ``t_sim_s`` (s since the run started)."""
        if self._file is None:
            return
        stamp = max(self._t0_us + round(t_sim_s * 1e6), 0)
        self._file.write(_STAMP.pack(stamp) + bytes(frame))
        self.frames += 1

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None

    def __enter__(self) -> TlogWriter:
        return self

    def __exit__(
        self,
        exc_type: type[BaseException] | None,
        exc: BaseException | None,
        tb: TracebackType | None,
    ) -> None:
        self.close()
