"""The MAVLink link strings the bridge opens (``KIND:HOST:PORT``), checked without opening
anything: the scenario schema checks `bridge.mavlink` and `gcs` URLs at load with the same
rule as the bridge (:mod:`uavxai.bridges.link`), without importing pymavlink or the bridge."""

from __future__ import annotations

from uavxai.errors import UserError

LINK_FORMS = (
    "udpout:HOST:PORT (send to a ground station and hear its replies)",
    "udpin:HOST:PORT (listen; answer the ground stations the bridge accepts)",
    "udp:HOST:PORT (same as udpin)",
    "udpbcast:HOST:PORT (broadcast, then talk to the peers that answer)",
    "tcp:HOST:PORT (connect)",
    "tcpin:HOST:PORT (accept one connection at a time)",
)
DATAGRAM_KINDS = {"udpout", "udpin", "udp", "udpbcast"}
STREAM_KINDS = {"tcp", "tcpin"}


def check_link(link: str) -> tuple[str, str, int]:
    """(kind, host, port) of a link string, or UserError naming the allowed forms."""
    parts = link.split(":") if isinstance(link, str) else []
    problem = None
    if len(parts) != 3:
        problem = "it must have the form KIND:HOST:PORT"
    elif parts[0] not in DATAGRAM_KINDS | STREAM_KINDS:
        problem = f"'{parts[0]}' is not a link kind this bridge opens"
    elif not parts[1]:
        problem = "the host is empty"
    elif not parts[2].isdigit() or not 0 < int(parts[2]) < 65536:
        problem = f"the port '{parts[2]}' is not a number between 1 and 65535"
    if problem:
        raise UserError(explain_link(link, problem))
    return parts[0], parts[1], int(parts[2])


def explain_link(link: object, problem: str) -> str:
    """The message for a link that cannot be used: what is wrong and the allowed forms."""
    return f"cannot use MAVLink link {link!r}: {problem}. Allowed forms: " + "; ".join(LINK_FORMS)
