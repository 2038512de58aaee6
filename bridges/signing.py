"""Checking incoming MAVLink 2 signatures in an order an outsider cannot turn against us.

pymavlink's own check (``MAVLink.check_signature``, 2.4.50) records a stream's timestamp
*before* it compares the signature. One forged frame signed with any key, on someone else's
stream (link id, system, component) and dated near 2^48, therefore makes every later frame of
that stream "old": issue 14 silenced the planner this way and the failsafe flew into a
collision. Here the signature is verified first, and only a frame that carries our key can move
a stream's timestamp or the clock new streams are judged against.

Each :class:`SignatureGate` keeps its own stream table, so the bridge gives the in-process
planner path and the external link one gate each: nothing that arrives on the link, signed or
not, can touch the state the planner's commands are checked against.

Rules (MAVLink 2 signing, as pymavlink applies them otherwise):

* unsigned frames pass only for message ids the policy accepts unsigned;
* a signed frame passes if its signature matches our key, and its timestamp is later than the
  last one of its stream, or, for a stream not seen yet, at most 60 s behind our clock (a
  rightly signed frame that fails the timestamp rule is a replay, counted as such);
* a frame that carries a signature that fails is refused even when its message id would be
  accepted unsigned: it is a forgery, not a keyless station.
"""

from __future__ import annotations

import hashlib
import hmac
import json
import logging
import os
import struct
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger(__name__)

ACCEPTED = "accepted"
REFUSED_UNSIGNED = "refused_unsigned"
REFUSED_BAD_SIGNATURE = "refused_bad_signature"
# Signed with our key but not new: a captured frame sent again (counted apart from forgeries,
# because it means someone records the link, not that someone guesses keys).
REFUSED_REPLAY = "refused_replay"

SIGNATURE_BLOCK = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN  # link id 1, timestamp 6, signature 6
# A new stream may start at most one minute behind our clock (timestamps count 10 us units).
NEW_STREAM_WINDOW = 60 * 100_000
MAX_TIMESTAMP = 2**48 - 1
# Our own clock follows accepted timestamps only up to here: past 2^48 pymavlink's signing
# keeps the low 48 bits, so our timestamps would wrap to 0 and every peer would refuse our
# frames as old. A peer with the key dated near the end of time must not do that to us.
# 2^32 units leave 11.9 hours of our own frames at one per 10 us.
CLOCK_CEILING = MAX_TIMESTAMP - 2**32
# MAVLink signing timestamps count 10 us units from 2015-01-01 00:00 UTC.
SIGNING_EPOCH_UNIX_S = 1420070400
STATE_FORMAT = 1
_V2_HEADER, _CRC = 10, 2


def wall_clock_timestamp() -> int:
    """Now as a MAVLink signing timestamp (the standard's starting point for a new sender)."""
    return int(max(time.time() - SIGNING_EPOCH_UNIX_S, 0) * 100_000)


def key_id(key: bytes) -> str:
    """A name for a key that does not reveal it (for files that persist signing state)."""
    return hashlib.sha256(b"uavxai-signing-state" + key).hexdigest()[:16]


def default_state_path(key: bytes) -> Path:
    """Where a user's runs keep the link's signing state for ``key`` between runs:
    ``$XDG_STATE_HOME/uavxai/`` (default ``~/.local/state/uavxai/``), one file per key."""
    base = os.environ.get("XDG_STATE_HOME") or Path.home() / ".local" / "state"
    return Path(base) / "uavxai" / f"mavlink-signing-{key_id(key)}.json"


class Clock:
    """Our side's signing time: the value new streams are judged against."""

    def __init__(self, timestamp: int | None = None) -> None:
        self.timestamp = wall_clock_timestamp() if timestamp is None else timestamp


class SignatureGate:
    """Accepts or refuses decoded frames of one source by their signature.

    ``clock`` is anything with an integer ``timestamp`` attribute (a pymavlink
    ``MAVLinkSigning`` of the sending codec, so that its outgoing timestamps stay ahead of what
    it has accepted, or a :class:`Clock`); ``accept_unsigned(message_id)`` is the policy for
    frames without a signature.
    """

    def __init__(
        self,
        key: bytes,
        clock: object | None = None,
        accept_unsigned: Callable[[int], bool] | None = None,
    ) -> None:
        self._key = bytes(key)
        self._clock = clock if clock is not None else Clock()
        self._accept_unsigned = accept_unsigned or (lambda _msg_id: False)
        self.streams: dict[tuple[int, int, int], int] = {}

    def check(self, frame: bytes, msg_id: int) -> str:
        """ACCEPTED, REFUSED_UNSIGNED, REFUSED_BAD_SIGNATURE or REFUSED_REPLAY for one
        CRC-checked frame."""
        signed = frame[0] == mavlink.PROTOCOL_MARKER_V2 and frame[2] & mavlink.MAVLINK_IFLAG_SIGNED
        if not signed:
            return ACCEPTED if self._accept_unsigned(msg_id) else REFUSED_UNSIGNED
        if len(frame) < _V2_HEADER + _CRC + SIGNATURE_BLOCK:
            return REFUSED_BAD_SIGNATURE
        # 1. The signature, over everything up to and including the timestamp. Nothing is
        #    recorded from a frame that fails it.
        expected = hashlib.sha256(self._key + bytes(frame[:-6])).digest()[:6]
        if not hmac.compare_digest(expected, bytes(frame[-6:])):
            return REFUSED_BAD_SIGNATURE
        # 2. The timestamp: replays and stale new streams are refused.
        link_id = frame[-13]
        low, high = struct.unpack("<IH", bytes(frame[-12:-6]))
        timestamp = low + (high << 32)
        stream = (link_id, frame[5], frame[6])  # link id, source system, source component
        last = self.streams.get(stream)
        if last is not None and timestamp <= last:
            return REFUSED_REPLAY
        if last is None and timestamp + NEW_STREAM_WINDOW < self._clock.timestamp:
            return REFUSED_REPLAY  # rightly signed long ago: a capture from an earlier run
        # 3. Only now: remember it.
        self.streams[stream] = timestamp
        self._clock.timestamp = max(self._clock.timestamp, min(timestamp, CLOCK_CEILING))
        return ACCEPTED

    # ------------------------------------------------------------------ persistence
    def load(self, path: Path) -> bool:
        """Take over the stream timestamps a previous run saved to ``path`` with this key, so
        its signed frames cannot be replayed into this run; False if there was nothing usable
        (no file, another key, a damaged file: logged, never fatal)."""
        try:
            with open(path, encoding="utf-8") as f:
                data = json.loads(f.read(1_000_000))
            if data.get("format") != STATE_FORMAT or data.get("key_id") != key_id(self._key):
                return False
            streams = {}
            for entry in data["streams"][:100_000]:
                link_id, system, component, timestamp = (int(v) for v in entry)
                if not (0 <= link_id < 256 and 0 <= system < 256 and 0 <= component < 256):
                    raise ValueError(f"stream {entry} out of range")
                streams[(link_id, system, component)] = min(max(timestamp, 0), MAX_TIMESTAMP)
            clock = min(max(int(data["clock"]), 0), CLOCK_CEILING)
        except FileNotFoundError:
            return False
        except (OSError, ValueError, TypeError, KeyError, AttributeError) as err:
            log.warning("ignoring MAVLink signing state %s: %s", path, err)
            return False
        for stream, timestamp in streams.items():
            self.streams[stream] = max(self.streams.get(stream, 0), timestamp)
        self._clock.timestamp = max(self._clock.timestamp, clock)
        return True

    def save(self, path: Path) -> None:
        """Write the stream timestamps to ``path`` (atomically; errors are logged)."""
        data = {
            "format": STATE_FORMAT,
            "key_id": key_id(self._key),
            "clock": int(self._clock.timestamp),
            "streams": [[*stream, ts] for stream, ts in sorted(self.streams.items())],
        }
        path = Path(path)
        try:
            path.parent.mkdir(parents=True, exist_ok=True)
            fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
            try:
                with os.fdopen(fd, "w", encoding="utf-8") as f:
                    json.dump(data, f)
                os.replace(tmp, path)
            except BaseException:
                Path(tmp).unlink(missing_ok=True)
                raise
        except OSError as err:
            log.warning("could not save MAVLink signing state to %s: %s", path, err)
