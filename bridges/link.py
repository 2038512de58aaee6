"""A pymavlink link string opened as a non-blocking byte pipe.

pymavlink's `mavlink_connection` opens the socket (binding, connecting, remembering UDP peers);
the bridge parses the bytes itself (`uavxai.bridges.framing`), so only the raw read/write side
of the connection is used. TCP sockets are read and written here directly because mavutil's
TCP classes print to stdout on every disconnect.
"""

from __future__ import annotations

import logging
import socket

from pymavlink import mavutil

from uavxai.errors import UserError

from .protocol import AUTOPILOT_COMPONENT

log = logging.getLogger(__name__)

LINK_FORMS = (
    "udpout:HOST:PORT (send to a ground station and hear its replies)",
    "udpin:HOST:PORT (listen; answer whoever sends)",
    "udp:HOST:PORT (same as udpin)",
    "udpbcast:HOST:PORT (broadcast, then talk to the first peer that answers)",
    "tcp:HOST:PORT (connect)",
    "tcpin:HOST:PORT (accept one connection at a time)",
)
_DATAGRAM_KINDS = {"udpout", "udpin", "udp", "udpbcast"}
_STREAM_KINDS = {"tcp", "tcpin"}
# A ground station's burst of more than ~256 datagrams overflows the default buffer between
# two polls; ask for more (the kernel caps it at net.core.rmem_max).
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
_READ_BYTES = 65536


def check_link(link: str) -> tuple[str, str, int]:
    """(kind, host, port) of a link string, or UserError naming the allowed forms."""
    parts = link.split(":") if isinstance(link, str) else []
    problem = None
    if len(parts) != 3:
        problem = "it must have the form KIND:HOST:PORT"
    elif parts[0] not in _DATAGRAM_KINDS | _STREAM_KINDS:
        problem = f"'{parts[0]}' is not a link kind this bridge opens"
    elif not parts[1]:
        problem = "the host is empty"
    elif not parts[2].isdigit() or not 0 < int(parts[2]) < 65536:
        problem = f"the port '{parts[2]}' is not a number between 1 and 65535"
    if problem:
        raise UserError(_explain(link, problem))
    return parts[0], parts[1], int(parts[2])


def _explain(link: object, problem: str) -> str:
    return f"cannot use MAVLink link {link!r}: {problem}. Allowed forms: " + "; ".join(LINK_FORMS)


class Link:
    """One open connection; `read()` never blocks and `write()` never raises."""

    def __init__(self, link: str, system_id: int) -> None:
        self.name = link
        self.kind, host, port = check_link(link)
        self.stream = self.kind in _STREAM_KINDS
        try:
            # mavutil resolves udpout hosts only when sending, and then swallows the error.
            socket.getaddrinfo(host, port)
            # retries=0: one connection attempt, no sleeping between retries.
            self._conn = mavutil.mavlink_connection(
                link, source_system=system_id, source_component=AUTOPILOT_COMPONENT, retries=0
            )
        except (OSError, ValueError) as err:
            raise UserError(_explain(link, f"opening it failed ({err})")) from err
        self._client: socket.socket | None = None
        self._peer_gone_logged = False
        if self.kind == "tcp":
            self._client = self._conn.port
        elif not self.stream:
            self._conn.port.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)

    def read(self) -> bytes:
        """One datagram, or the stream bytes waiting; b"" when there are none."""
        if not self.stream:
            try:
                return bytes(self._conn.recv() or b"")
            except OSError as err:
                log.debug("MAVLink link %s: receive failed: %s", self.name, err)
                return b""
        client = self._stream_client()
        if client is None:
            return b""
        try:
            data = client.recv(_READ_BYTES)
        except BlockingIOError:
            return b""
        except OSError:
            data = b""
        if not data:
            self._drop_client()
        return data

    def write(self, data: bytes) -> None:
        if not self.stream:
            self._conn.write(data)  # mavudp swallows socket errors
            return
        client = self._stream_client()
        if client is None:
            return
        try:
            # A partial send of a frame is possible under back-pressure; the receiver's
            # framing resynchronises on the next frame.
            client.send(data)
        except BlockingIOError:
            pass
        except OSError:
            self._drop_client()

    def close(self) -> None:
        if self._client is not None and self._client is not self._conn.port:
            self._client.close()
        self._client = None
        self._conn.close()

    def _stream_client(self) -> socket.socket | None:
        if self._client is None and self.kind == "tcpin":
            try:
                self._client, peer = self._conn.listen.accept()
            except OSError:
                return None
            self._client.setblocking(False)
            self._peer_gone_logged = False
            log.info("MAVLink link %s: peer %s connected", self.name, peer)
        return self._client

    def _drop_client(self) -> None:
        if not self._peer_gone_logged:
            log.warning("MAVLink link %s: the peer closed the connection", self.name)
            self._peer_gone_logged = True
        if self.kind == "tcpin" and self._client is not None:
            self._client.close()
            self._client = None  # ready to accept the next ground station
