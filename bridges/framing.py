"""Robust MAVLink framing: bytes in, decoded messages and an account of everything dropped.

pymavlink's own parser, after a frame fails its CRC, discards the whole length the (possibly
corrupted) header announced, and a truncated datagram leaves bytes in its buffer that corrupt
the next one. Here a frame whose CRC fails costs only its first byte: scanning resumes at the
next start marker, so one damaged frame never takes a good neighbour with it. pymavlink's
``decode()`` still does the CRC and payload work; signatures are checked by a
`uavxai.bridges.signing.SignatureGate`, verified before any timestamp is recorded.

Datagram sources (UDP, the planner's ``feed``) carry whole frames, so an incomplete frame at the
end of a datagram is garbage. Stream sources (TCP) keep it until more bytes arrive.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from pymavlink.dialects.v20 import common as mavlink

from .signing import (
    ACCEPTED,
    REFUSED_BAD_SIGNATURE,
    REFUSED_REPLAY,
    REFUSED_UNSIGNED,
    SignatureGate,
)

_MAGIC_V1 = mavlink.PROTOCOL_MARKER_V1
_MAGIC_V2 = mavlink.PROTOCOL_MARKER_V2
_HEADER_V1, _HEADER_V2, _CRC = 6, 10, 2
_SIGNED = mavlink.MAVLINK_IFLAG_SIGNED
_SIGNATURE = mavlink.MAVLINK_SIGNATURE_BLOCK_LEN
MAX_FRAME_BYTES = _HEADER_V2 + 255 + _CRC + _SIGNATURE
_NOT_A_FRAME = 0


@dataclass
class Parsed:
    """What one chunk of bytes held."""

    messages: list = field(default_factory=list)
    malformed: int = 0  # runs of bytes that are not a frame (garbage, truncation, bad CRC)
    unknown: int = 0  # frames of message types outside the dialect (cannot be checked)
    refused_unsigned: int = 0  # refused by the signing policy: no signature
    refused_bad_signature: int = 0  # refused by the signing policy: not signed with our key
    refused_replay: int = 0  # signed with our key, but not newer than its stream: a replay


class FrameReader:
    """Splits bytes from one source into frames and decodes them with `codec`."""

    def __init__(
        self, codec: mavlink.MAVLink, stream: bool, gate: SignatureGate | None = None
    ) -> None:
        """`codec` decodes (it must hold no signing key: signatures are `gate`'s business,
        checked in an order pymavlink does not keep; see `uavxai.bridges.signing`)."""
        if codec.signing.secret_key is not None:
            raise ValueError("FrameReader's codec must not hold a signing key; pass a gate")
        self._codec = codec
        self._stream = stream
        self._gate = gate
        self._tail = b""

    def push(self, data: bytes) -> Parsed:
        buf = self._tail + bytes(data)
        self._tail = b""
        out = Parsed()
        in_garbage = False
        i, n = 0, len(buf)
        while i < n:
            start = _next_marker(buf, i)
            if start != i:
                in_garbage = True
                if start < 0:
                    break
                i = start
            length = _frame_length(buf, i)
            if length == _NOT_A_FRAME:
                in_garbage, i = True, i + 1
                continue
            if length is None or i + length > n:
                if self._stream and n - i < MAX_FRAME_BYTES:
                    self._tail = buf[i:]
                    break
                in_garbage, i = True, i + 1  # a frame never spans datagrams: a false marker
                continue
            frame = buf[i : i + length]
            if not self._decode(frame, out):
                in_garbage, i = True, i + 1
                continue
            if in_garbage:
                out.malformed += 1
                in_garbage = False
            i += length
        if in_garbage:
            out.malformed += 1
        return out

    def _decode(self, frame: bytes, out: Parsed) -> bool:
        """Decode one candidate frame into `out`; False if it is not a frame after all."""
        try:
            msg = self._codec.decode(bytearray(frame))
        except Exception:  # hostile bytes must never escape as an exception
            return False
        if isinstance(msg, mavlink.MAVLink_unknown):
            # No CRC extra, so not even the CRC could be checked: dropped, and it touches no
            # signing state.
            out.unknown += 1
            return True
        # The CRC passed (decode checks it), so this is a real frame; now its signature.
        verdict = ACCEPTED if self._gate is None else self._gate.check(frame, msg.get_msgId())
        if verdict == REFUSED_UNSIGNED:
            out.refused_unsigned += 1
        elif verdict == REFUSED_BAD_SIGNATURE:
            out.refused_bad_signature += 1
        elif verdict == REFUSED_REPLAY:
            out.refused_replay += 1
        else:
            out.messages.append(msg)
        return True


def _next_marker(buf: bytes, start: int) -> int:
    v1, v2 = buf.find(_MAGIC_V1, start), buf.find(_MAGIC_V2, start)
    if v1 < 0 or v2 < 0:
        return max(v1, v2)
    return min(v1, v2)


def _frame_length(buf: bytes, i: int) -> int | None:
    """Total length of the frame starting at `i` per its header: None while the header is
    incomplete, _NOT_A_FRAME if no valid frame has this header."""
    if buf[i] == _MAGIC_V1:
        return _HEADER_V1 + buf[i + 1] + _CRC if i + 1 < len(buf) else None
    if i + 2 >= len(buf):
        return None
    payload, incompat = buf[i + 1], buf[i + 2]
    if incompat & ~_SIGNED:
        return _NOT_A_FRAME  # unknown incompatibility flags: not a frame we can read
    return _HEADER_V2 + payload + _CRC + (_SIGNATURE if incompat & _SIGNED else 0)


def split_frames(data: bytes) -> list[bytes]:
    """Whole frames packed back to back (by our own codecs) as a list of frames: a .tlog
    stamps each frame, and a counter counts frames, not chunks. Bytes that are no frame end
    the split (they are dropped: nothing of ours writes them)."""
    out, i, n = [], 0, len(data)
    while i < n:
        magic = data[i]
        if magic == _MAGIC_V2 and i + 3 <= n:
            size = _HEADER_V2 + data[i + 1] + _CRC + (_SIGNATURE if data[i + 2] & _SIGNED else 0)
        elif magic == _MAGIC_V1 and i + 2 <= n:
            size = _HEADER_V1 + data[i + 1] + _CRC
        else:
            break
        if i + size > n:
            break
        out.append(bytes(data[i : i + size]))
        i += size
    return out
