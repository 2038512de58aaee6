"""MavlinkBridge: the ownship's MAVLink face. Commands in, telemetry out, on simulated time.

Every flight command reaches the dynamics through `_dispatch`, whether its bytes came from the
in-process planner (`feed`) or from a peer on the link (`poll`), so the planner's commands are
real MAVLink frames that pass the same parsing, addressing and signing checks as anyone's.

Signing policy (with a key): every outgoing frame is signed. Incoming frames must carry a valid
signature, except HEARTBEAT, PARAM_REQUEST_LIST and PARAM_REQUEST_READ, which are accepted
unsigned: they change nothing, a ground station without the key can still see the vehicle and
its parameters (signing authenticates, it does not hide), and every command it sends is
refused and counted. A frame that carries a signature that fails is refused whatever its type:
that is a forgery, not a station without the key. Signatures are verified before any stream
timestamp is recorded (`uavxai.bridges.signing`), and the planner's path (`feed`) and the link
(`poll`) keep separate stream tables, so nothing from the link can make the planner's commands
look old.

Limits: every command is clamped to the world and the aircraft before it reaches the sink
(height to ``alt_limits_m``, airspeed to ``speed_limits_mps``, bank to ``bank_limit_rad``,
along-track acceleration to ``accel_limit_mps2``, orbit centres to ``xy_limits_m``). A clamped
COMMAND_LONG/COMMAND_INT is still acknowledged MAV_RESULT_ACCEPTED (the aircraft does fly it,
at the limit) with ``result_param2 = ACK_CLAMPED`` and a STATUSTEXT warning naming the clamp,
which is what ground stations show the operator; setpoints, which have no acknowledgement, get
the STATUSTEXT (at most one per kind every few simulated seconds) and the ``clamped_commands``
counter.
"""

from __future__ import annotations

import logging
import math
import socket
import time
from collections.abc import Sequence
from pathlib import Path
from types import SimpleNamespace
from typing import Protocol

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.errors import UserError

from . import telemetry
from .framing import FrameReader, Parsed, split_frames
from .link import Link, Peer
from .missions import MissionServer
from .operator import SETPOINT_REFUSAL, Decoded, Limits, OperatorCommand, decode
from .params import ParamTable
from .protocol import (
    AUTOPILOT_COMPONENT,
    SetpointError,
    accel_from_position_target,
    bank_from_attitude_target,
    enable_signing,
    new_codec,
)
from .signing import Clock, SignatureGate
from .tlog import TlogWriter
from .watchdog import CommandWatchdog

log = logging.getLogger(__name__)

ACCEPTED_UNSIGNED = frozenset(
    {
        mavlink.MAVLINK_MSG_ID_HEARTBEAT,
        mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_LIST,
        mavlink.MAVLINK_MSG_ID_PARAM_REQUEST_READ,
    }
)
HOME_PERIOD_S = 5.0
# Mission-protocol messages that only read: any vehicle may answer a broadcast of these.
_MISSION_READS = frozenset({"MISSION_REQUEST_LIST", "MISSION_REQUEST_INT", "MISSION_REQUEST"})
# Commands that predate MAV_CMD_REQUEST_MESSAGE, and the message each one asks for.
_LEGACY_REQUESTS = {
    mavlink.MAV_CMD_GET_HOME_POSITION: mavlink.MAVLINK_MSG_ID_HOME_POSITION,
    mavlink.MAV_CMD_REQUEST_AUTOPILOT_CAPABILITIES: mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION,
}
# COMMAND_ACK.result_param2 of an accepted command that was flown at a limit, not as asked
# (0 = unused, as MAVLink asks of command-specific result codes).
ACK_CLAMPED = 1
# Setpoints arrive at 10 Hz or more; say that they are clamped at most this often (simulated s).
CLAMP_NOTICE_PERIOD_S = 5.0
# Defaults of the limits: the scenario defaults of world.h, world.x and world.y, the uav_fw
# autopilot's speed range, and the largest avoidance.bank_limit_deg and avoidance.accel_mps2 a
# scenario may set (the autopilot applies the scenario's own bank limit as well).
DEFAULT_ALT_LIMITS_M = (50.0, 300.0)
DEFAULT_SPEED_LIMITS_MPS = (12.0, 30.0)
DEFAULT_BANK_LIMIT_RAD = math.radians(60.0)
DEFAULT_ACCEL_LIMIT_MPS2 = 10.0
DEFAULT_XY_LIMITS_M = ((0.0, 2000.0), (0.0, 2000.0))
# Bound the work one poll() does, so a flooding peer cannot stall the simulation loop.
_MAX_READS_PER_POLL = 1000
_COUNTERS = (
    "messages_in",  # decoded frames, whatever their fate
    "messages_out",  # frames written to the link
    "commands",  # setpoints and commands obeyed
    "rejected_commands",  # addressed to us but unusable (bad values, unsupported frame)
    "ignored_other_target",  # commands addressed to another system or component
    "ignored_messages",  # valid messages the bridge has no use for
    "malformed",  # runs of bytes that were not a valid frame
    "unknown_messages",  # frames of message types outside the common dialect
    "refused_unsigned",
    "refused_bad_signature",
    "refused_replay",  # signed with our key but not newer than its stream: a replayed capture
    "refused_unknown_peer",  # from a host or system not in ground_stations (and not signed)
    "param_requests",
    "param_sets_refused",
    "operator_commands",  # a ground station's aims taken (modes, heights, speeds, points)
    "operator_refused",  # a ground station's commands refused (setpoints, modes not flown)
    "failsafe_events",
    "clamped_commands",  # obeyed, but at a limit of the world or the aircraft
)


class CommandSink(Protocol):
    """What the bridge commands: the ownship's autopilot setpoints (the JSBSim world)."""

    def command_ownship(
        self,
        bank_cmd_rad: float | None = None,
        accel_cmd_mps2: float | None = None,
        speed_target_mps: float | None = None,
        alt_target_m: float | None = None,
        speed_max_mps: float | None = None,
    ) -> None: ...

    def command_orbit(
        self, x: float, y: float, radius_m: float, clockwise: bool = True
    ) -> None: ...


class MavlinkBridge:
    """The ownship as MAVLink system `system_id`, component 1.

    `frame` converts ENU to geodetic; `sink` receives obeyed setpoints; `link` is a pymavlink
    connection string (None: no external peer, only `feed`). `signing_key` (32 bytes) turns on
    MAVLink 2 signing both ways. `params` are extra read-only parameters for ground stations.
    `home` is the home point (x, y, h) in the local frame; by default the ground point below the
    ownship's first published position. Rates are in Hz of simulated time.

    Limits every command is clamped to (see the module docstring): `alt_limits_m` (h band,
    m above the local origin; the lower limit must be above the ground), `speed_limits_mps`
    (airspeed), `bank_limit_rad` (|bank|), `accel_limit_mps2` (|along-track acceleration|),
    `xy_limits_m` ((x0, x1), (y0, y1)) for orbit centres. `signing_state` (with a key) is a
    file where the link's stream timestamps are kept between runs, so signed frames captured
    in one run cannot be replayed into the next; without it, MAVLink's new-stream rule lets a
    capture in for about a minute.

    `ground_stations` are the (MAVLink system id, host) pairs allowed to command over the link
    (see `_link_source`); everyone else is heard but neither obeyed nor answered, and only
    ground stations (or peers that sign with the key) receive telemetry on udpin. `tlog` is a
    new file that receives every frame decoded and every frame sent, in MAVProxy's .tlog
    format. `traffic_emitter` is the ADS-B emitter category (MAVLink's ADSB_EMITTER_TYPE) of
    the intruders' aircraft, which their ADSB_VEHICLE carries.
    """

    def __init__(
        self,
        system_id: int,
        frame: LocalFrame,
        sink: CommandSink,
        link: str | None = None,
        signing_key: bytes | None = None,
        command_timeout_s: float = 3.0,
        params: dict[str, float] | None = None,
        home: tuple[float, float, float] | None = None,
        telemetry_hz: float = 10.0,
        adsb_hz: float = 2.0,
        alt_limits_m: tuple[float, float] = DEFAULT_ALT_LIMITS_M,
        speed_limits_mps: tuple[float, float] = DEFAULT_SPEED_LIMITS_MPS,
        bank_limit_rad: float = DEFAULT_BANK_LIMIT_RAD,
        accel_limit_mps2: float = DEFAULT_ACCEL_LIMIT_MPS2,
        xy_limits_m: tuple[tuple[float, float], tuple[float, float]] = DEFAULT_XY_LIMITS_M,
        signing_state: str | Path | None = None,
        ground_stations: Sequence[tuple[int, str]] = (),
        tlog: str | Path | None = None,
        traffic_emitter: int = mavlink.ADSB_EMITTER_TYPE_UAV,
    ) -> None:
        if not 1 <= system_id <= 255:
            raise ValueError(f"MAVLink system id must be 1..255, got {system_id}")
        self._init_limits(
            alt_limits_m, speed_limits_mps, bank_limit_rad, accel_limit_mps2, xy_limits_m
        )
        self._clamp_noticed: dict[str, float] = {}
        self.system_id = system_id
        self.frame = frame
        self.counters: dict[str, int] = dict.fromkeys(_COUNTERS, 0)
        self._sink = sink
        self._home_setting = home
        self._home = home
        self._refusal_reported = False
        self._watchdog = CommandWatchdog(command_timeout_s)
        self._params = self._param_table(
            system_id, command_timeout_s, telemetry_hz, adsb_hz, signing_key, params
        )
        self._gates = {
            "heartbeat": telemetry.RateGate(1.0),
            "home": telemetry.RateGate(1.0 / HOME_PERIOD_S),
            "vehicle": telemetry.RateGate(telemetry_hz),
            "adsb": telemetry.RateGate(adsb_hz),
        }
        self._previous_attitude: tuple[float, np.ndarray] | None = None
        self._now: float | None = None
        # Publish every intruder's exact state as ADSB_VEHICLE (no surveillance model); off
        # when a surveillance model's reports are relayed instead.
        self.truth_adsb = True
        self.traffic_emitter = traffic_emitter  # their ADSB_VEHICLE's emitter_type
        self.phase = "transit"  # the mission phase, announced in STATUSTEXT
        self.mode = "AUTO"  # the flight mode ground stations see (uavxai.sim.operator)
        self._operator_commands: list[OperatorCommand] = []
        self._from_link = False  # the message being handled came from a ground station
        self.power = telemetry.Power()  # battery and throttle, when the dynamics model them

        self._init_link(link, system_id, signing_key, signing_state, ground_stations, tlog)
        self.missions = MissionServer(self._send)
        self._handlers = {
            "SET_ATTITUDE_TARGET": self._on_attitude_target,
            "SET_POSITION_TARGET_LOCAL_NED": self._on_position_target,
            "COMMAND_LONG": self._on_command_long,
            "COMMAND_INT": self._on_command_int,
            "PARAM_REQUEST_LIST": self._on_param_request_list,
            "PARAM_REQUEST_READ": self._on_param_request_read,
            "PARAM_SET": self._on_param_set,
            **dict.fromkeys(MissionServer.MESSAGES, self._on_mission),
        }

    def _init_limits(
        self,
        alt_limits_m: tuple[float, float],
        speed_limits_mps: tuple[float, float],
        bank_limit_rad: float,
        accel_limit_mps2: float,
        xy_limits_m: tuple[tuple[float, float], tuple[float, float]],
    ) -> None:
        """Check and keep the limits every command is clamped to (see the module docstring);
        a bad limit is refused at construction, before any command meets it."""
        self._alt_limits = _interval("alt_limits_m", alt_limits_m, lowest=0.0)
        self._speed_limits = _interval("speed_limits_mps", speed_limits_mps, lowest=0.0)
        self._xy_limits = (
            _interval("xy_limits_m[0]", xy_limits_m[0]),
            _interval("xy_limits_m[1]", xy_limits_m[1]),
        )
        if not (math.isfinite(bank_limit_rad) and 0 < bank_limit_rad < math.pi / 2):
            raise ValueError(f"bank_limit_rad must lie in (0, pi/2), got {bank_limit_rad}")
        if not (math.isfinite(accel_limit_mps2) and accel_limit_mps2 > 0):
            raise ValueError(f"accel_limit_mps2 must be positive, got {accel_limit_mps2}")
        self._bank_limit = float(bank_limit_rad)
        self._accel_limit = float(accel_limit_mps2)
        self.limits = Limits(self._alt_limits, self._speed_limits, self._xy_limits)

    def _param_table(
        self,
        system_id: int,
        command_timeout_s: float,
        telemetry_hz: float,
        adsb_hz: float,
        signing_key: bytes | None,
        params: dict[str, float] | None,
    ) -> ParamTable:
        """The bridge's own read-only parameters (its settings and limits) plus ``params``,
        which may not shadow them."""
        own = {
            "BRG_SYSID": float(system_id),
            "BRG_CMD_TIMEOUT": float(command_timeout_s),
            "BRG_TELEM_HZ": float(telemetry_hz),
            "BRG_ADSB_HZ": float(adsb_hz),
            "BRG_SIGNING": 1.0 if signing_key is not None else 0.0,
            # the limits commands are clamped to, so an operator can see them before sending
            "BRG_ALT_MIN": self._alt_limits[0],
            "BRG_ALT_MAX": self._alt_limits[1],
            "BRG_SPD_MIN": self._speed_limits[0],
            "BRG_SPD_MAX": self._speed_limits[1],
            "BRG_BANK_LIM": math.degrees(self._bank_limit),
            "BRG_ACCEL_LIM": self._accel_limit,
        }
        clash = sorted(set(own) & set(params or {}))
        if clash:
            raise ValueError(f"parameter names {clash} are the bridge's own")
        return ParamTable(own | dict(params or {}))

    def _init_link(
        self,
        link: str | None,
        system_id: int,
        signing_key: bytes | None,
        signing_state: str | Path | None,
        ground_stations: Sequence[tuple[int, str]],
        tlog: str | Path | None,
    ) -> None:
        """Open the link (if any) and the telemetry log, and set up the codec, the signature
        gates, the readers of both inputs (the in-process feed and the link) and who may
        command over the link."""
        self._ground_stations = _ground_stations(ground_stations)
        self._listed_hosts = frozenset(host for _, host in self._ground_stations)
        self._unknown_peer_reported = False
        self._tlog = None  # before the link, so a refused file leaves no socket open
        if tlog is not None:
            self._tlog = TlogWriter(tlog, time.time())
        try:
            self._link = Link(link, system_id) if link is not None else None
        except BaseException:
            if self._tlog is not None:
                self._tlog.close()
            raise
        # One codec signs what we send; decoding is done by key-less codecs, because the
        # signature check belongs to the gates (pymavlink's records a timestamp before it
        # checks the signature: the forged-frame attack of issue 14).
        self._codec = new_codec(SimpleNamespace(write=self._write), system_id, AUTOPILOT_COMPONENT)
        feed_gate = link_gate = None
        self._signing_state = Path(signing_state) if signing_state and signing_key else None
        if signing_key is not None:
            enable_signing(self._codec, signing_key)
            accept = ACCEPTED_UNSIGNED.__contains__
            # The planner's path has its own gate and clock: the link cannot touch them.
            feed_gate = SignatureGate(signing_key, Clock(), accept)
            link_gate = SignatureGate(signing_key, self._codec.signing, accept)
            if self._signing_state is not None:
                link_gate.load(self._signing_state)
        self._link_gate = link_gate
        decoder = new_codec(None, system_id, AUTOPILOT_COMPONENT)
        self._feed_reader = FrameReader(decoder, stream=False, gate=feed_gate)
        self._script_reader = FrameReader(decoder, stream=False)
        self._link_reader = (
            FrameReader(decoder, stream=self._link.stream, gate=link_gate) if self._link else None
        )

    # ------------------------------------------------------------------ input
    def feed(self, data: bytes) -> int:
        """Decode and obey MAVLink bytes handed over in-process by the onboard planner (whole
        frames, like one datagram); returns the number of commands obeyed."""
        return self._handle(self._feed_reader.push(data))

    def feed_operator(self, data: bytes) -> int:
        """Frames of the scenario's scripted operator (``operator.commands``): decoded as a
        ground station's, from a station the scenario itself allows; returns the number of
        aims taken."""
        return self._handle(self._script_reader.push(data), operator=True)

    def mission_items_local(self) -> list[tuple]:
        """The uploaded mission in the local frame: (seq, command, params, x, y, h) per item,
        heights above home (the local origin's ground); x, y, h are 0 for items that are no
        place (RTL, DO_CHANGE_SPEED)."""
        out = []
        for item in self.missions.items:
            x = y = h = 0.0
            if item.positional:
                lx, ly, _ = self.frame.to_local(item.lat_deg, item.lon_deg, 0.0)
                x, y = float(lx), float(ly)
                h = float(item.height_above_home(self.frame.alt0) or 0.0)
            params = tuple(p if math.isfinite(p) else 0.0 for p in item.params)
            out.append((item.seq, item.command, params, x, y, h))
        return out

    def take_operator_commands(self) -> list[OperatorCommand]:
        """The ground stations' aims received since the last call, oldest first."""
        out, self._operator_commands = self._operator_commands, []
        return out

    def poll(self) -> int:
        """Read and obey whatever the link has received, without blocking; returns the number
        of commands obeyed."""
        if self._link is None:
            return 0
        obeyed = 0
        for _ in range(_MAX_READS_PER_POLL):
            got = self._link.read()
            if got is None:
                break
            data, peer = got
            if self._link_gate is None and peer[0] not in self._listed_hosts:
                # Without a key, only listed hosts may speak. Refused before any parsing, so
                # a flood of spoofed datagrams costs one set lookup each.
                self._refuse_peer(peer)
                continue
            obeyed += self._handle(self._link_reader.push(data), peer)
        return obeyed

    # ------------------------------------------------------------------ time and output
    def tick(self, t: float) -> None:
        """Advance simulated time to `t` (s) and run the command watchdog."""
        if self._now is not None and t < self._now:
            self._restart_clock()
        self._now = t
        if self._watchdog.advance(t):
            self.counters["failsafe_events"] += 1
            log.warning(
                "no command for %.1f s: wings level, holding speed and altitude",
                self._watchdog.timeout_s,
            )
            self._sink.command_ownship(bank_cmd_rad=0.0, accel_cmd_mps2=0.0)
        self.missions.tick(t)

    def publish(self, state: TrafficState) -> None:
        """Advance to `state.t` and send whatever telemetry is due (call every ~0.1 s)."""
        self.tick(state.t)
        if self._home is None:
            self._home = (float(state.pos[0, 0]), float(state.pos[0, 1]), 0.0)
        if self._link is None:
            return
        t, gates = state.t, self._gates
        if gates["heartbeat"].due(t):
            self._send(telemetry.heartbeat(self.failsafe_active, self.mode))
            self._send(self.missions.current_message())
        if gates["home"].due(t):
            self._send(telemetry.home_position(self.frame, self._home, t))
        if gates["vehicle"].due(t):
            self._send(telemetry.sys_status(self.counters["malformed"], self.power))
            self._send(telemetry.global_position_int(state, self.frame))
            self._send(telemetry.attitude(state, self._body_rates(state)))
            self._send(telemetry.vfr_hud(state, self.frame, self.power))
        if self.truth_adsb and gates["adsb"].due(t):
            for msg in telemetry.adsb_vehicles(state, self.frame, self.traffic_emitter):
                self._send(msg)

    def announce(self, text: str, severity: int = mavlink.MAV_SEVERITY_NOTICE) -> None:
        """A STATUSTEXT to the ground stations (mission phases, failsafes); MAVLink carries
        50 characters, the rest is cut."""
        data = text[:50].encode("ascii", "replace")
        self._send(mavlink.MAVLink_statustext_message(severity, data))
        log.info("%s", text)

    def relay(self, frames: bytes) -> None:
        """Forward frames packed elsewhere to the link: the ADS-B receiver's ADSB_VEHICLE
        reports, which the ground station then shows as traffic (with ``truth_adsb`` off,
        they replace the exact traffic the bridge would otherwise publish)."""
        for frame in split_frames(frames):
            self._write(frame)

    @property
    def failsafe_active(self) -> bool:
        return self._watchdog.tripped

    def close(self) -> None:
        if self._link_gate is not None and self._signing_state is not None:
            self._link_gate.save(self._signing_state)
            self._signing_state = None
        if self._link is not None:
            self._link.close()
            self._link = None
        if self._tlog is not None:
            self._tlog.close()
            self._tlog = None

    def __enter__(self) -> MavlinkBridge:
        return self

    def __exit__(self, *_exc) -> None:
        self.close()

    # ------------------------------------------------------------------ internals
    def _handle(self, parsed: Parsed, peer: Peer | None = None, operator: bool = False) -> int:
        """Obey what ``parsed`` holds; ``peer`` is who sent it over the link (None: in-process,
        trusted: the onboard planner's feed, or with ``operator`` the scenario's scripted
        ground station, whose commands are aims like any ground station's)."""
        c = self.counters
        c["malformed"] += parsed.malformed
        c["unknown_messages"] += parsed.unknown
        c["refused_unsigned"] += parsed.refused_unsigned
        c["refused_bad_signature"] += parsed.refused_bad_signature
        c["refused_replay"] += parsed.refused_replay
        refused = parsed.refused_unsigned + parsed.refused_bad_signature + parsed.refused_replay
        if refused and not self._refusal_reported:
            self._refusal_reported = True
            log.warning(
                "refused a MAVLink message that was unsigned, signed with another key or "
                "replayed: "
                "signing is on, so commands need the bridge's key; further refusals are "
                "only counted"
            )
        obeyed = 0
        from_link = self._from_link = peer is not None or operator
        for msg in parsed.messages:
            c["messages_in"] += 1
            if self._tlog is not None:
                self._tlog.write(self._now or 0.0, msg.get_msgbuf())
            if peer is not None and not self._link_source(msg, peer):
                continue
            if from_link:  # a ground station commands aims, never setpoints
                read = decode(msg, self.frame, self.limits)
                if read is not None:
                    obeyed += self._operator(msg, read)
                    continue
            handler = self._handlers.get(msg.get_type())
            if handler is None:
                c["ignored_messages"] += 1
            elif handler(msg):
                obeyed += 1
        self._from_link = False
        return obeyed

    def _operator(self, msg, read: Decoded) -> int:
        """A ground station's command: its aim queued for the episode's operator, or refused;
        acknowledged (COMMAND_LONG/INT) and explained (STATUSTEXT) to the station."""
        if not self._addressed_to_me(msg, allow_broadcast=msg.get_type() == "SET_MODE"):
            return 0
        acked = msg.get_type() in ("COMMAND_LONG", "COMMAND_INT")
        if read.command is None:
            self.counters["operator_refused"] += 1
            if read.refused == SETPOINT_REFUSAL:
                self._notice("setpoint", read.refused)  # at most one notice every few s
            else:
                self.announce(read.refused or "command refused", mavlink.MAV_SEVERITY_WARNING)
            if acked:
                self._ack(msg, read.result)
            return 0
        if read.notes:
            self.counters["clamped_commands"] += 1
            for note in read.notes:
                self.announce(f"clamped: {note}", mavlink.MAV_SEVERITY_WARNING)
        if read.command.kind == "set_current":  # the mission's own business
            try:
                self.missions.set_current(read.command.seq)
            except ValueError:
                self.counters["operator_refused"] += 1
                self.announce(f"no mission item {read.command.seq}", mavlink.MAV_SEVERITY_WARNING)
                if acked:
                    self._ack(msg, mavlink.MAV_RESULT_DENIED)
                return 0
        if acked:
            self._ack(msg, mavlink.MAV_RESULT_ACCEPTED, ACK_CLAMPED if read.notes else 0)
        self.counters["operator_commands"] += 1
        self._operator_commands.append(read.command)
        return 1

    def _link_source(self, msg, peer: Peer) -> bool:
        """Whether ``msg`` from ``peer`` on the link may be handled; admits the peer to the
        link's telemetry when it has earned it.

        Without a key: only a listed (system, host) pair (the host alone was checked before
        parsing). With a key: commands must be signed (the gate has checked the signature)
        and, if ground stations are listed, come from one; HEARTBEAT and PARAM_REQUEST_*,
        which the gate lets through unsigned, are answered for signed peers and listed hosts
        only, because an answer is telemetry."""
        listed = (msg.get_srcSystem(), peer[0]) in self._ground_stations
        if self._link_gate is None:
            admitted = allowed = listed
        else:
            buf = msg.get_msgbuf()
            signed = buf[0] == mavlink.PROTOCOL_MARKER_V2 and bool(
                buf[2] & mavlink.MAVLINK_IFLAG_SIGNED
            )  # a signed frame that reached here passed the gate: the signature is ours
            admitted = signed or peer[0] in self._listed_hosts
            if msg.get_msgId() in ACCEPTED_UNSIGNED:
                allowed = admitted
            else:
                allowed = signed and (listed or not self._ground_stations)
        if admitted:
            self._link.admit(peer)
        if not allowed:
            self._refuse_peer(peer)
        return allowed

    def _refuse_peer(self, peer: Peer) -> None:
        self.counters["refused_unknown_peer"] += 1
        if not self._unknown_peer_reported:
            self._unknown_peer_reported = True
            log.warning(
                "refused MAVLink from %s (port %d): it is not a ground station this bridge "
                "obeys; to allow it, list its system id and host in the scenario's "
                "bridge.ground_stations%s. Further refusals are only counted",
                peer[0],
                peer[1],
                " and sign with the bridge's key" if self._link_gate is not None else "",
            )

    def _send(self, msg) -> None:
        self._codec.send(msg)

    def _write(self, frame: bytes) -> None:
        """Where the codec puts each outgoing frame."""
        if self._link is not None:
            self._link.write(frame)
            self.counters["messages_out"] += 1
            if self._tlog is not None:
                self._tlog.write(self._now or 0.0, frame)

    def _addressed_to_me(self, msg, allow_broadcast: bool = False) -> bool:
        systems = (self.system_id, 0) if allow_broadcast else (self.system_id,)
        if msg.target_system in systems and msg.target_component in (0, AUTOPILOT_COMPONENT):
            return True
        self.counters["ignored_other_target"] += 1
        return False

    def _obey(self, **setpoint: float) -> bool:
        self._sink.command_ownship(**setpoint)
        self.counters["commands"] += 1
        silence = self._watchdog.note_command()
        if silence is not None:
            log.info("commands resumed after %.1f s of silence", silence)
        return True

    def _reject(self, why: str) -> bool:
        self.counters["rejected_commands"] += 1
        log.debug("command rejected: %s", why)
        return False

    def _on_attitude_target(self, msg) -> bool:
        if not self._addressed_to_me(msg):
            return False
        try:
            bank = bank_from_attitude_target(msg)
        except SetpointError as why:
            return self._reject(str(why))
        limit = self._bank_limit
        flown, clamped = _limited(bank, -limit, limit)
        if clamped:
            self._clamped(
                "bank", f"bank {math.degrees(bank):.0f} deg clamped to {math.degrees(flown):.0f}"
            )
        return self._obey(bank_cmd_rad=flown)

    def _on_position_target(self, msg) -> bool:
        if not self._addressed_to_me(msg):
            return False
        try:
            accel = accel_from_position_target(msg)
        except SetpointError as why:
            return self._reject(str(why))
        limit = self._accel_limit
        flown, clamped = _limited(accel, -limit, limit)
        if clamped:
            self._clamped("accel", f"accel {accel:.3g} m/s2 clamped to {flown:.3g}")
        return self._obey(accel_cmd_mps2=flown)

    def _on_command_long(self, msg) -> bool:
        """The onboard planner's DO_CHANGE_SPEED / DO_CHANGE_ALTITUDE (flown), and message
        requests from anyone (a ground station's aims are decoded in :meth:`_operator`)."""
        if not self._addressed_to_me(msg):
            return False
        if msg.command in (mavlink.MAV_CMD_DO_CHANGE_SPEED, mavlink.MAV_CMD_DO_CHANGE_ALTITUDE):
            return self._fly_planner_command(msg)
        reply = self._requested_message(msg)
        if reply is None:
            self._ack(msg, mavlink.MAV_RESULT_UNSUPPORTED)
            self.counters["ignored_messages"] += 1
            return False
        self._ack(msg, mavlink.MAV_RESULT_ACCEPTED)
        self._send(reply)
        return False

    def _on_command_int(self, msg) -> bool:
        """The onboard planner's MAV_CMD_DO_ORBIT (the mission's loiter about a point)."""
        if not self._addressed_to_me(msg):
            return False
        if msg.command != mavlink.MAV_CMD_DO_ORBIT:
            self._ack(msg, mavlink.MAV_RESULT_UNSUPPORTED)
            self.counters["ignored_messages"] += 1
            return False
        return self._fly_planner_command(msg)

    def _fly_planner_command(self, msg) -> bool:
        """A command of the onboard planner, read by the same decoder as an operator's and
        held to the same limits, then written to the autopilot."""
        read = decode(msg, self.frame, self.limits)
        cmd = read.command if read is not None else None
        if cmd is None:
            return self._reject(read.refused if read is not None else "unknown command")
        if read.notes:
            self.counters["clamped_commands"] += 1
            for note in read.notes:
                self.announce(f"clamped: {note}", mavlink.MAV_SEVERITY_WARNING)
        if cmd.kind == "speed":  # the operator's airspeed, flown as the autopilot's ceiling
            return self._obey(speed_target_mps=cmd.speed_mps, speed_max_mps=cmd.speed_mps)
        if cmd.kind == "altitude":
            return self._obey(alt_target_m=cmd.h)
        self._obey(alt_target_m=cmd.h, speed_target_mps=cmd.speed_mps)
        self._sink.command_orbit(cmd.x, cmd.y, cmd.radius_m, cmd.clockwise)
        return True

    def _requested_message(self, msg):
        """The reply to a request for a message this bridge can send on demand, or None."""
        if msg.command == mavlink.MAV_CMD_REQUEST_MESSAGE:
            wanted = int(msg.param1) if math.isfinite(msg.param1) else None
        else:
            wanted = _LEGACY_REQUESTS.get(msg.command)
        if wanted == mavlink.MAVLINK_MSG_ID_HOME_POSITION and self._home is not None:
            return telemetry.home_position(self.frame, self._home, self._now or 0.0)
        if wanted == mavlink.MAVLINK_MSG_ID_AUTOPILOT_VERSION:
            return telemetry.autopilot_version()
        return None

    def _ack(self, msg, result: int, result_param2: int = 0) -> None:
        if not self._from_link:
            return  # the onboard planner's commands are not acknowledged onto the ground link
        self._send(
            mavlink.MAVLink_command_ack_message(
                msg.command,
                result,
                0,
                result_param2,
                msg.get_srcSystem(),
                msg.get_srcComponent(),
            )
        )

    # ------------------------------------------------------------------ limits
    def _clamped(self, kind: str, text: str) -> None:
        """A setpoint flown at a limit: counted; announced at most every few seconds."""
        self.counters["clamped_commands"] += 1
        self._notice(kind, text)

    def _notice(self, kind: str, text: str) -> None:
        """A warning about setpoints, which come at 10 Hz or more: said at most once every
        few simulated seconds per kind, logged otherwise."""
        now = self._now if self._now is not None else 0.0
        last = self._clamp_noticed.get(kind)
        if last is None or not 0 <= now - last < CLAMP_NOTICE_PERIOD_S:
            self._clamp_noticed[kind] = now
            self.announce(text, mavlink.MAV_SEVERITY_WARNING)
        else:
            log.debug("%s", text)

    def _on_mission(self, msg) -> bool:
        # Uploads, clears and set-current change the vehicle: only when addressed to it.
        if self._addressed_to_me(msg, allow_broadcast=msg.get_type() in _MISSION_READS):
            self.missions.handle(msg, self._now if self._now is not None else 0.0)
        return False  # not a flight command

    def _on_param_request_list(self, msg) -> bool:
        if self._addressed_to_me(msg, allow_broadcast=True):
            self.counters["param_requests"] += 1
            for index in range(len(self._params)):
                self._send(self._params.value_message(index))
        return False

    def _on_param_request_read(self, msg) -> bool:
        if self._addressed_to_me(msg, allow_broadcast=True):
            self.counters["param_requests"] += 1
            index = self._params.find(msg.param_id, msg.param_index)
            if index is not None:
                self._send(self._params.value_message(index))
        return False

    def _on_param_set(self, msg) -> bool:
        # Parameters mirror the scenario and are read-only. Echoing the unchanged value is how
        # a vehicle tells a ground station that a set did not take.
        if self._addressed_to_me(msg):
            self.counters["param_sets_refused"] += 1
            index = self._params.find(msg.param_id, -1)
            if index is not None:
                self._send(self._params.value_message(index))
                why = f"{msg.param_id} read-only: set it in the scenario"
            else:
                why = f"no parameter {msg.param_id}"
            self.announce(why, mavlink.MAV_SEVERITY_WARNING)
        return False

    def _body_rates(self, state: TrafficState) -> np.ndarray:
        previous, self._previous_attitude = self._previous_attitude, (state.t, state.att[0].copy())
        if previous is None:
            return np.zeros(3)
        t0, att0 = previous
        return telemetry.body_rates(att0, state.att[0], state.t - t0)

    def _restart_clock(self) -> None:
        """Simulated time went backwards: a new episode. Start rates and watchdog afresh."""
        self._watchdog.restart()
        for gate in self._gates.values():
            gate.restart()
        self._previous_attitude = None
        self._home = self._home_setting


def _limited(value: float, lo: float, hi: float) -> tuple[float, bool]:
    """``value`` held to [lo, hi], and whether that was a clamp worth reporting. MAVLink
    carries these values as float32 (a quaternion, for the bank), so a command sent exactly
    at a limit may arrive a few parts in 10^8 beyond it: held, but not reported."""
    flown = min(max(value, lo), hi)
    tolerance = 1e-6 * max(1.0, abs(lo), abs(hi))
    return flown, not lo - tolerance <= value <= hi + tolerance


def _ground_stations(pairs: Sequence[tuple[int, str]]) -> frozenset[tuple[int, str]]:
    """The (system id, numeric IPv4 host) pairs allowed to command; host names are resolved
    once, here, because the link reports its peers by address."""
    allowed = set()
    for pair in pairs:
        try:
            system, host = pair
            system = int(system)
            if not 1 <= system <= 255:
                raise ValueError(f"system id {system} is not 1..255")
            address = socket.getaddrinfo(str(host), None, socket.AF_INET)[0][4][0]
        except (OSError, TypeError, ValueError) as err:
            raise UserError(
                f"bridge.ground_stations: cannot use {pair!r} as a (system id, host) pair: {err}"
            ) from err
        allowed.add((system, address))
    return frozenset(allowed)


def _interval(name: str, value, lowest: float = -math.inf) -> tuple[float, float]:
    lo, hi = (float(v) for v in value)
    if not (math.isfinite(lo) and math.isfinite(hi) and lowest < lo <= hi):
        raise ValueError(f"{name} must be finite, ordered and above {lowest:g}, got {value}")
    return lo, hi
