"""The MAVLink mission protocol, vehicle side: ground stations upload, download and clear the
ownship's mission (https://mavlink.io/en/services/mission.html), as MAVProxy's ``wp load`` /
``wp list`` / ``wp clear`` and QGroundControl do.

ArduPilot's conventions, which those ground stations expect of an ArduPlane: seq 0 of a
mission is HOME and is not flown; flying starts at seq 1. Only MAV_MISSION_TYPE_MISSION is
kept: a fence or rally download is an empty list and an upload of one is refused.

A mission is replaced only by a whole, valid upload: an upload that times out, is cancelled
or carries one item this vehicle cannot fly leaves the accepted mission as it was. Every
field of every message comes from a peer that may be hostile, so nothing here trusts a count,
a sequence number or a float: memory is bounded by ``max_items`` and `MissionServer.handle`
raises for no field value.

Flying the mission is not done here: the flight side reads ``items``, ``current`` and
``version`` and calls ``reached`` / ``set_current`` as it goes.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from pymavlink.dialects.v20 import common as mavlink

log = logging.getLogger(__name__)

MISSION = mavlink.MAV_MISSION_TYPE_MISSION
SUPPORTED_COMMANDS = frozenset(
    {
        mavlink.MAV_CMD_NAV_WAYPOINT,
        mavlink.MAV_CMD_NAV_LOITER_UNLIM,
        mavlink.MAV_CMD_NAV_LOITER_TURNS,
        mavlink.MAV_CMD_NAV_LOITER_TIME,
        mavlink.MAV_CMD_NAV_RETURN_TO_LAUNCH,
        mavlink.MAV_CMD_NAV_TAKEOFF,
        mavlink.MAV_CMD_DO_CHANGE_SPEED,
    }
)
# Commands whose x, y, z are a place to fly to; the others ignore them.
POSITIONAL_COMMANDS = frozenset(
    {
        mavlink.MAV_CMD_NAV_WAYPOINT,
        mavlink.MAV_CMD_NAV_LOITER_UNLIM,
        mavlink.MAV_CMD_NAV_LOITER_TURNS,
        mavlink.MAV_CMD_NAV_LOITER_TIME,
        mavlink.MAV_CMD_NAV_TAKEOFF,
    }
)
# z is metres above home in these frames, metres above mean sea level in the others.
RELATIVE_FRAMES = frozenset(
    {mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT, mavlink.MAV_FRAME_GLOBAL_RELATIVE_ALT_INT}
)
MSL_FRAMES = frozenset({mavlink.MAV_FRAME_GLOBAL, mavlink.MAV_FRAME_GLOBAL_INT})
GLOBAL_FRAMES = RELATIVE_FRAMES | MSL_FRAMES
# Non-positional items may also come in MAV_FRAME_MISSION; ground stations often send them in
# the mission's global frame, which then means nothing either.
NON_POSITIONAL_FRAMES = GLOBAL_FRAMES | {mavlink.MAV_FRAME_MISSION}
# Parameters (1-based) an item is meaningless without. MAVLink lets NaN in any other parameter
# mean "default / unchanged" (QGroundControl sends the waypoint yaw, param4, as NaN), so NaN is
# refused only here; an infinite parameter is refused everywhere.
REQUIRED_PARAMS = {
    mavlink.MAV_CMD_NAV_LOITER_TURNS: (1,),  # turns
    mavlink.MAV_CMD_NAV_LOITER_TIME: (1,),  # seconds
    mavlink.MAV_CMD_DO_CHANGE_SPEED: (2,),  # m/s (-1: no change)
}
_INVALID_PARAM = (
    mavlink.MAV_MISSION_INVALID_PARAM1,
    mavlink.MAV_MISSION_INVALID_PARAM2,
    mavlink.MAV_MISSION_INVALID_PARAM3,
    mavlink.MAV_MISSION_INVALID_PARAM4,
)
_NO_MISSION_TOTAL = 0xFFFF  # MISSION_CURRENT.total when there is no mission (MAVLink's value)
_UINT16_MAX = 0xFFFF


@dataclass(frozen=True)
class MissionItem:
    """One accepted mission item, in the units it was sent in (degrees, metres, MAV_* ids).

    ``lat_deg`` / ``lon_deg`` are x / y in degrees (MISSION_ITEM_INT's degE7 / 1e7);
    ``alt_m`` is z as sent, in ``frame`` (use `height_above_home`). Items that are not a
    place (RTL, DO_CHANGE_SPEED) keep 0, 0, 0 there. ``params`` may hold NaN where MAVLink
    lets it mean "default" (e.g. a waypoint's yaw, a loiter's radius).
    """

    seq: int
    command: int
    frame: int
    params: tuple[float, float, float, float]
    lat_deg: float
    lon_deg: float
    alt_m: float
    autocontinue: bool

    @property
    def positional(self) -> bool:
        return self.command in POSITIONAL_COMMANDS

    def height_above_home(self, home_alt_msl_m: float) -> float | None:
        """Metres above home: z in relative frames, z - home's MSL altitude in MSL frames;
        None for items that are not a place."""
        if not self.positional:
            return None
        if self.frame in RELATIVE_FRAMES:
            return self.alt_m
        return self.alt_m - home_alt_msl_m

    def to_message(self, target_system: int, target_component: int, current: bool):
        """The item as MISSION_ITEM_INT (the only form MAVLink still recommends)."""
        return mavlink.MAVLink_mission_item_int_message(
            target_system,
            target_component,
            self.seq,
            self.frame,
            self.command,
            int(current),
            int(self.autocontinue),
            *self.params,
            round(self.lat_deg * 1e7),
            round(self.lon_deg * 1e7),
            self.alt_m,
            MISSION,
        )


class MissionItemError(ValueError):
    """An item this vehicle will not fly; ``result`` is the MAV_MISSION_RESULT to answer."""

    def __init__(self, result: int, why: str) -> None:
        super().__init__(why)
        self.result = result


def item_from_message(msg) -> MissionItem:
    """A MissionItem from a decoded MISSION_ITEM_INT or MISSION_ITEM, or MissionItemError with
    the MAV_MISSION_RESULT that names what is wrong."""
    command, frame = int(msg.command), int(msg.frame)
    if command not in SUPPORTED_COMMANDS:
        raise MissionItemError(mavlink.MAV_MISSION_UNSUPPORTED, f"command {command}")
    positional = command in POSITIONAL_COMMANDS
    if frame not in (GLOBAL_FRAMES if positional else NON_POSITIONAL_FRAMES):
        raise MissionItemError(
            mavlink.MAV_MISSION_UNSUPPORTED_FRAME, f"frame {frame} for command {command}"
        )
    params = (float(msg.param1), float(msg.param2), float(msg.param3), float(msg.param4))
    required = REQUIRED_PARAMS.get(command, ())
    for n, value in enumerate(params, start=1):
        if math.isinf(value) or (n in required and math.isnan(value)):
            raise MissionItemError(_INVALID_PARAM[n - 1], f"param{n} {value} of command {command}")
    if not positional:
        return MissionItem(msg.seq, command, frame, params, 0.0, 0.0, 0.0, bool(msg.autocontinue))
    lat, lon = _degrees(msg)
    alt = float(msg.z)
    if not (math.isfinite(lat) and abs(lat) <= 90):
        raise MissionItemError(mavlink.MAV_MISSION_INVALID_PARAM5_X, f"latitude {lat}")
    if not (math.isfinite(lon) and abs(lon) <= 180):
        raise MissionItemError(mavlink.MAV_MISSION_INVALID_PARAM6_Y, f"longitude {lon}")
    if not math.isfinite(alt):
        raise MissionItemError(mavlink.MAV_MISSION_INVALID_PARAM7, f"altitude {alt}")
    return MissionItem(msg.seq, command, frame, params, lat, lon, alt, bool(msg.autocontinue))


def _degrees(msg) -> tuple[float, float]:
    """x, y in degrees: MISSION_ITEM_INT carries degE7 (int32, so finite but possibly far
    out of range), legacy MISSION_ITEM float degrees (possibly NaN)."""
    if msg.get_type() == "MISSION_ITEM_INT":
        return int(msg.x) / 1e7, int(msg.y) / 1e7
    return float(msg.x), float(msg.y)


@dataclass
class _Upload:
    """An upload in progress: who sends it, what has arrived, when we last asked."""

    partner: tuple[int, int]
    count: int
    received: list[MissionItem]
    asked_at: float
    retries_left: int

    @property
    def expected(self) -> int:
        return len(self.received)


class MissionServer:
    """The vehicle's side of the mission protocol (type MISSION only).

    `send` puts a pymavlink message on the link (the bridge's ``_send``). `handle` takes each
    decoded mission-protocol message, already checked for addressing and signing; `tick`
    retries an unanswered request after ``request_timeout_s`` of simulated time and gives the
    upload up (MAV_MISSION_OPERATION_CANCELLED, mission unchanged) after ``retries`` of them.
    """

    # The message types `handle` consumes (for a dispatcher's table).
    MESSAGES = (
        "MISSION_COUNT",
        "MISSION_ITEM_INT",
        "MISSION_ITEM",
        "MISSION_REQUEST_LIST",
        "MISSION_REQUEST_INT",
        "MISSION_REQUEST",
        "MISSION_CLEAR_ALL",
        "MISSION_SET_CURRENT",
        "MISSION_ACK",
        "MISSION_WRITE_PARTIAL_LIST",
        "MISSION_REQUEST_PARTIAL_LIST",
    )

    def __init__(
        self,
        send: Callable[[Any], None],
        *,
        max_items: int = 500,
        request_timeout_s: float = 1.0,
        retries: int = 5,
    ) -> None:
        if not 1 <= max_items <= _UINT16_MAX:
            raise ValueError(f"max_items must be 1..{_UINT16_MAX}, got {max_items}")
        if not (math.isfinite(request_timeout_s) and request_timeout_s > 0):
            raise ValueError(f"request_timeout_s must be positive, got {request_timeout_s}")
        if retries < 0:
            raise ValueError(f"retries must be >= 0, got {retries}")
        self._send = send
        self.max_items = max_items
        self.request_timeout_s = float(request_timeout_s)
        self.retries = retries
        self.items: list[MissionItem] = []
        self.current = 0
        self.version = 0
        self._state = mavlink.MISSION_STATE_NO_MISSION
        self._upload: _Upload | None = None
        # The partner and size of the last accepted upload, to repeat a lost final ACK.
        self._last_upload: tuple[tuple[int, int], int] | None = None
        self._handlers: dict[str, Callable[[Any, float], None]] = {
            "MISSION_COUNT": self._on_count,
            "MISSION_ITEM_INT": self._on_item,
            "MISSION_ITEM": self._on_item,
            "MISSION_REQUEST_LIST": self._on_request_list,
            "MISSION_REQUEST_INT": self._on_request,
            "MISSION_REQUEST": self._on_request,
            "MISSION_CLEAR_ALL": self._on_clear_all,
            "MISSION_SET_CURRENT": self._on_set_current,
            "MISSION_ACK": self._on_ack,
            "MISSION_WRITE_PARTIAL_LIST": self._on_partial_list,
            "MISSION_REQUEST_PARTIAL_LIST": self._on_partial_list,
        }

    # ------------------------------------------------------------------ the flight side
    @property
    def uploading(self) -> bool:
        return self._upload is not None

    def set_current(self, seq: int) -> None:
        """Make `seq` the current item (the flight side moving on) and say so."""
        if not 0 <= seq < max(len(self.items), 1):
            raise ValueError(f"no mission item {seq} (the mission has {len(self.items)})")
        self.current = seq
        if len(self.items) > 1:
            self._state = mavlink.MISSION_STATE_ACTIVE
        self._send(self.current_message())

    def reached(self, seq: int) -> None:
        """Say that item `seq` has been reached (MISSION_ITEM_REACHED)."""
        if not 0 <= seq < len(self.items):
            raise ValueError(f"no mission item {seq} (the mission has {len(self.items)})")
        self._state = (
            mavlink.MISSION_STATE_COMPLETE
            if seq == len(self.items) - 1
            else mavlink.MISSION_STATE_ACTIVE
        )
        self._send(mavlink.MAVLink_mission_item_reached_message(seq))

    def current_message(self) -> mavlink.MAVLink_mission_current_message:
        """MISSION_CURRENT for periodic telemetry. ``total`` leaves HOME out (MAVLink's rule
        for autopilots that keep home as item 0), so the last item's seq equals it."""
        total = len(self.items) - 1 if len(self.items) > 1 else _NO_MISSION_TOTAL
        return mavlink.MAVLink_mission_current_message(self.current, total, self._state)

    # ------------------------------------------------------------------ the link side
    def handle(self, msg, now: float) -> bool:
        """Answer one mission-protocol message (sim time `now`, s); False if `msg` is not one.
        Never raises: a hostile peer must not stop the simulation loop."""
        handler = self._handlers.get(msg.get_type())
        if handler is None:
            return False
        try:
            handler(msg, now)
        except Exception:  # a bug met by some field value: log it, keep flying
            log.exception("mission protocol: could not handle %s", msg.get_type())
        return True

    def tick(self, now: float) -> None:
        """Retry or give up an upload whose request went unanswered (sim time `now`, s)."""
        up = self._upload
        if up is None:
            return
        if now < up.asked_at:  # time went backwards (a new episode): count from here
            up.asked_at = now
        if now - up.asked_at < self.request_timeout_s:
            return
        if up.retries_left <= 0:
            log.warning(
                "mission upload from %s stalled at item %d of %d: given up, mission kept",
                up.partner,
                up.expected,
                up.count,
            )
            self._upload = None
            self._ack(up.partner, mavlink.MAV_MISSION_OPERATION_CANCELLED)
            return
        up.retries_left -= 1
        self._request(up, now)

    # ------------------------------------------------------------------ upload
    def _on_count(self, msg, now: float) -> None:
        partner, count, kind = _source(msg), int(msg.count), _mission_type(msg)
        if kind != MISSION:
            self._ack(partner, mavlink.MAV_MISSION_UNSUPPORTED, kind)
            return
        if self._upload is not None and self._upload.partner != partner:
            # One upload at a time; the one under way goes on.
            self._ack(partner, mavlink.MAV_MISSION_DENIED)
            return
        self._upload = None  # the same station starting again abandons its last attempt
        if count > self.max_items:
            log.warning("mission upload of %d items refused: at most %d", count, self.max_items)
            self._ack(partner, mavlink.MAV_MISSION_NO_SPACE)
            return
        if count == 0:
            self._replace([], partner)
            return
        self._upload = _Upload(partner, count, [], now, self.retries)
        self._request(self._upload, now)

    def _on_item(self, msg, now: float) -> None:
        partner, kind, up = _source(msg), _mission_type(msg), self._upload
        if kind != MISSION:
            self._ack(partner, mavlink.MAV_MISSION_UNSUPPORTED, kind)
            return
        if up is None or up.partner != partner:
            # The final ACK may have been lost, so the station sends its last item again.
            if self._last_upload == (partner, msg.seq + 1) and up is None:
                self._ack(partner, mavlink.MAV_MISSION_ACCEPTED)
            return
        if msg.seq != up.expected:
            # A duplicate or one from the future: ask again for the one we need.
            self._request(up, now)
            return
        try:
            item = item_from_message(msg)
        except MissionItemError as why:
            log.warning("mission upload refused at item %d: %s", msg.seq, why)
            self._upload = None
            self._ack(partner, why.result)
            return
        up.received.append(item)
        up.retries_left = self.retries
        if up.expected < up.count:
            self._request(up, now)
        else:
            self._upload = None
            self._replace(up.received, partner)

    def _replace(self, items: list[MissionItem], partner: tuple[int, int]) -> None:
        self.items = list(items)
        self.version += 1
        self.current = 1 if len(items) > 1 else 0
        self._state = (
            mavlink.MISSION_STATE_NOT_STARTED
            if len(items) > 1
            else mavlink.MISSION_STATE_NO_MISSION
        )
        self._last_upload = (partner, len(items))
        log.info("mission of %d items accepted (version %d)", len(items), self.version)
        self._ack(partner, mavlink.MAV_MISSION_ACCEPTED)

    def _request(self, up: _Upload, now: float) -> None:
        up.asked_at = now
        system, component = up.partner
        self._send(
            mavlink.MAVLink_mission_request_int_message(system, component, up.expected, MISSION)
        )

    # ------------------------------------------------------------------ download and the rest
    def _on_request_list(self, msg, now: float) -> None:
        system, component = _source(msg)
        kind = _mission_type(msg)
        count = len(self.items) if kind == MISSION else 0
        self._send(mavlink.MAVLink_mission_count_message(system, component, count, kind))

    def _on_request(self, msg, now: float) -> None:
        # Legacy MISSION_REQUEST gets MISSION_ITEM_INT too, as MAVLink's deprecation of the
        # float messages asks; every ground station that uploads missions understands it.
        partner, kind, seq = _source(msg), _mission_type(msg), int(msg.seq)
        if kind != MISSION or not 0 <= seq < len(self.items):
            self._ack(partner, mavlink.MAV_MISSION_INVALID_SEQUENCE, kind)
            return
        self._send(self.items[seq].to_message(*partner, current=seq == self.current))

    def _on_clear_all(self, msg, now: float) -> None:
        partner, kind = _source(msg), _mission_type(msg)
        if kind in (MISSION, mavlink.MAV_MISSION_TYPE_ALL):
            if self._upload is not None:
                if self._upload.partner != partner:
                    self._ack(partner, mavlink.MAV_MISSION_DENIED, kind)
                    return
                self._upload = None
            self.items = []
            self.version += 1
            self.current = 0
            self._state = mavlink.MISSION_STATE_NO_MISSION
            self._last_upload = None
            log.info("mission cleared (version %d)", self.version)
        # Fence and rally points: there are none to clear, which is what was asked.
        self._ack(partner, mavlink.MAV_MISSION_ACCEPTED, kind)

    def _on_set_current(self, msg, now: float) -> None:
        seq = int(msg.seq)
        if 0 <= seq < len(self.items):
            self.current = seq
            self._send(self.current_message())
            return
        # MISSION_SET_CURRENT has no acknowledgement: an operator is told in words.
        text = f"Mission seq {seq} invalid: {len(self.items)} items"
        self._send(
            mavlink.MAVLink_statustext_message(mavlink.MAV_SEVERITY_WARNING, text.encode("ascii"))
        )

    def _on_ack(self, msg, now: float) -> None:
        # The ground station's ACK closes a download (nothing to do), or cancels its upload.
        up = self._upload
        if up is not None and up.partner == _source(msg) and _mission_type(msg) == MISSION:
            log.warning(
                "mission upload cancelled by %s (result %s): mission kept", up.partner, msg.type
            )
            self._upload = None

    def _on_partial_list(self, msg, now: float) -> None:
        # Partial reads and writes are optional in MAVLink; refusing them at once spares the
        # ground station a timeout (it then does a whole upload or download).
        self._ack(_source(msg), mavlink.MAV_MISSION_UNSUPPORTED, _mission_type(msg))

    def _ack(self, partner: tuple[int, int], result: int, kind: int = MISSION) -> None:
        system, component = partner
        self._send(mavlink.MAVLink_mission_ack_message(system, component, result, kind))


def _source(msg) -> tuple[int, int]:
    return msg.get_srcSystem(), msg.get_srcComponent()


def _mission_type(msg) -> int:
    """The message's mission_type; a MAVLink 1 frame has none and means MISSION."""
    kind = getattr(msg, "mission_type", MISSION)
    return kind if isinstance(kind, int) and 0 <= kind <= 255 else MISSION
