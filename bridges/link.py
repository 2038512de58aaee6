"""A MAVLink link string opened as a non-blocking byte pipe that knows who its peers are.

UDP sockets are opened here, not by pymavlink: its ``udpin`` remembers every sender forever and
sends every telemetry frame to each, so one byte from each of 20,000 spoofed addresses slowed a
run from 5-8x real time to 0.08x (issue 28), and telemetry went to any address that claimed to
be a ground station. Here a sender is only *heard*: `read` returns who sent the datagram, and
it receives nothing until the bridge vouches for it with `admit`. Known peers are few
(``max_peers``, the least recently heard evicted first) and forgotten after ``peer_timeout_s``
of silence, so neither a flood nor a long run makes `write` slower.

TCP sockets are still opened by pymavlink (its connect and accept are fine) but read and
written here directly, because mavutil's TCP classes print to stdout on every disconnect; the
one connected peer is the peer.
"""

from __future__ import annotations

import logging
import socket
import time
from collections import OrderedDict
from collections.abc import Callable

from pymavlink import mavutil

from uavxai.errors import UserError
from uavxai.link_url import STREAM_KINDS, check_link, explain_link

from .protocol import AUTOPILOT_COMPONENT

log = logging.getLogger(__name__)

Peer = tuple[str, int]  # (host, port)

# A ground station's burst of more than ~256 datagrams overflows the default buffer between
# two polls; ask for more (the kernel caps it at net.core.rmem_max).
RECEIVE_BUFFER_BYTES = 4 * 1024 * 1024
_READ_BYTES = 65536


def _ipv4(host: str, port: int) -> Peer:
    """The numeric address of ``host``, resolved once (never on every send)."""
    return socket.getaddrinfo(host, port, socket.AF_INET, socket.SOCK_DGRAM)[0][4][:2]


class PeerTable:
    """Peers that receive telemetry: bounded, least recently heard evicted, silent ones
    expire. Kept apart from the sockets so its rules can be read (and tested) on their own."""

    def __init__(self, max_peers: int, timeout_s: float, clock: Callable[[], float]) -> None:
        if max_peers < 1:
            raise ValueError(f"max_peers must be at least 1, got {max_peers}")
        if not timeout_s > 0:
            raise ValueError(f"peer_timeout_s must be positive, got {timeout_s}")
        self._max = max_peers
        self._timeout = timeout_s
        self._clock = clock
        self._heard: OrderedDict[Peer, float] = OrderedDict()  # oldest first

    def add(self, peer: Peer) -> None:
        """Know ``peer`` (or refresh it), evicting the least recently heard beyond the bound."""
        self._heard[peer] = self._clock()
        self._heard.move_to_end(peer)
        while len(self._heard) > self._max:
            gone, _ = self._heard.popitem(last=False)
            log.info("MAVLink peer %s:%d dropped: too many peers", *gone)

    def heard(self, peer: Peer) -> bool:
        """Refresh ``peer`` if it is known (and not yet expired); whether it was."""
        if peer not in self._heard:
            return False
        self.expire()
        if peer not in self._heard:
            return False
        self.add(peer)
        return True

    def expire(self) -> None:
        deadline = self._clock() - self._timeout
        # Oldest first: stop at the first peer heard recently enough.
        while self._heard:
            peer, last = next(iter(self._heard.items()))
            if last > deadline:
                break
            del self._heard[peer]
            log.info("MAVLink peer %s:%d dropped: silent for %.0f s", *peer, self._timeout)

    def current(self) -> list[Peer]:
        self.expire()
        return list(self._heard)


class Link:
    """One open connection; `read()` never blocks and `write()` never raises.

    ``udpout``: the target is a permanent peer. ``udpin``/``udp``: no peer until `admit`.
    ``udpbcast``: broadcast until someone answers, then send to those who answered (bounded and
    expiring like admitted peers; broadcast again once they are all gone). TCP: the connected
    peer. ``clock`` (seconds, monotonic) times peer expiry; tests inject their own.
    """

    def __init__(
        self,
        link: str,
        system_id: int,
        *,
        max_peers: int = 8,
        peer_timeout_s: float = 30.0,
        clock: Callable[[], float] = time.monotonic,
    ) -> None:
        self.name = link
        self.kind, host, port = check_link(link)
        self.stream = self.kind in STREAM_KINDS
        self._table = PeerTable(max_peers, peer_timeout_s, clock)
        self._target: Peer | None = None  # udpout's ground station, udpbcast's broadcast
        self._sock: socket.socket | None = None
        self._conn = None  # pymavlink's TCP connection
        self._client: socket.socket | None = None
        self._client_peer: Peer | None = None
        self._peer_gone_logged = False
        try:
            if self.stream:
                socket.getaddrinfo(host, port)
                # retries=0: one connection attempt, no sleeping between retries.
                self._conn = mavutil.mavlink_connection(
                    link, source_system=system_id, source_component=AUTOPILOT_COMPONENT, retries=0
                )
            else:
                self._sock = self._open_udp(host, port)
        except (OSError, ValueError) as err:
            raise UserError(explain_link(link, f"opening it failed ({err})")) from err
        if self.kind == "tcp":
            self._client = self._conn.port
            self._client_peer = _peer_of(self._client)

    def _open_udp(self, host: str, port: int) -> socket.socket:
        address = _ipv4(host, port)
        sock = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
        try:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, RECEIVE_BUFFER_BYTES)
            sock.setblocking(False)
            if self.kind in ("udpin", "udp"):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_REUSEADDR, 1)
                sock.bind(address)
            else:
                if self.kind == "udpbcast":
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
                # Bound now, so replies can be read before the first send, and only on the
                # interface that reaches the target (not on every interface, as an implicit
                # bind at the first send would be).
                sock.bind((_local_address_towards(address), 0))
                self._target = address
        except OSError:
            sock.close()
            raise
        return sock

    # ------------------------------------------------------------------ reading
    def read(self) -> tuple[bytes, Peer] | None:
        """One datagram (UDP) or the stream bytes waiting (TCP), and who sent them; None when
        nothing waits. Reading never makes a sender a peer (except udpbcast's answers)."""
        if self._sock is not None:
            return self._read_datagram()
        client = self._stream_client()
        if client is None:
            return None
        try:
            data = client.recv(_READ_BYTES)
        except BlockingIOError:
            return None
        except OSError:
            data = b""
        peer = self._client_peer or ("", 0)
        if not data:
            self._drop_client()
            return None
        return data, peer

    def _read_datagram(self) -> tuple[bytes, Peer] | None:
        while True:
            try:
                data, address = self._sock.recvfrom(_READ_BYTES)
            except (BlockingIOError, InterruptedError):
                return None
            except ConnectionRefusedError:
                continue  # a send of ours met a closed port: reported once, read on
            except OSError as err:
                log.debug("MAVLink link %s: receive failed: %s", self.name, err)
                return None
            peer = (address[0], address[1])
            if not self._table.heard(peer) and self.kind == "udpbcast":
                self._table.add(peer)  # today's udpbcast: whoever answers is talked to
            return data, peer

    # ------------------------------------------------------------------ writing
    def write(self, data: bytes) -> None:
        """Send ``data`` to every known peer; errors are logged at debug level, never raised."""
        if self._sock is not None:
            for peer in self._send_to():
                try:
                    self._sock.sendto(data, peer)
                except OSError as err:
                    log.debug("MAVLink link %s: send to %s failed: %s", self.name, peer, err)
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

    def _send_to(self) -> list[Peer]:
        peers = self._table.current()
        if self.kind == "udpout":
            return [self._target, *(p for p in peers if p != self._target)]
        if self.kind == "udpbcast" and not peers:
            return [self._target]
        return peers

    def admit(self, peer: Peer) -> None:
        """The bridge vouches for ``peer`` (an allowed ground station, or one that signed
        correctly): it receives telemetry from now on, until silent for peer_timeout_s."""
        if self.stream:
            return  # the connected peer is the only one a stream has
        self._table.add((peer[0], int(peer[1])))

    @property
    def peers(self) -> list[Peer]:
        """The peers `write` sends to now (expired ones dropped)."""
        if self.stream:
            return [self._client_peer] if self._client is not None and self._client_peer else []
        peers = self._table.current()
        if self.kind == "udpout" and self._target not in peers:
            return [self._target, *peers]
        return peers

    def close(self) -> None:
        if self._sock is not None:
            self._sock.close()
            self._sock = None
        if self._conn is not None:
            if self._client is not None and self._client is not self._conn.port:
                self._client.close()
            self._conn.close()
            self._conn = None
        self._client = None

    # ------------------------------------------------------------------ TCP
    def _stream_client(self) -> socket.socket | None:
        if self._client is None and self.kind == "tcpin" and self._conn is not None:
            try:
                self._client, address = self._conn.listen.accept()
            except OSError:
                return None
            self._client.setblocking(False)
            self._client_peer = (address[0], address[1])
            self._peer_gone_logged = False
            log.info("MAVLink link %s: peer %s connected", self.name, address)
        return self._client

    def _drop_client(self) -> None:
        if not self._peer_gone_logged:
            log.warning("MAVLink link %s: the peer closed the connection", self.name)
            self._peer_gone_logged = True
        if self.kind == "tcpin" and self._client is not None:
            self._client.close()
            self._client = None  # ready to accept the next ground station
            self._client_peer = None


def _local_address_towards(target: Peer) -> str:
    """The address of our interface that routes to ``target`` (a connected UDP socket sends
    nothing: it only asks the routing table)."""
    with socket.socket(socket.AF_INET, socket.SOCK_DGRAM) as probe:
        probe.setsockopt(socket.SOL_SOCKET, socket.SO_BROADCAST, 1)
        probe.connect(target)
        return probe.getsockname()[0]


def _peer_of(sock: socket.socket) -> Peer | None:
    try:
        address = sock.getpeername()
    except OSError:
        return None
    return address[0], address[1]
