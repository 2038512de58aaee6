"""MAVLink side of the co-simulation, installed as `uavxai.bridges`.

The wire is MAVLink 2 everywhere. The bridge's own codec imports pymavlink's v20 `common`
dialect directly, so its bytes are MAVLink 2 whatever the import order. `pymavlink.mavutil`
(used here only to open sockets, and by tests, tools and ground-station scripts in this process)
picks its dialect from the environment variable MAVLINK20 *when it is first imported*, and with
MAVLink 1 its `setup_signing()` silently signs nothing. So the variable is set before any
pymavlink import below, and if mavutil was already imported without it, its dialect is selected
again; connections opened before that stay MAVLink 1 until they see a MAVLink 2 frame.
"""

import os
import sys

os.environ["MAVLINK20"] = "1"


def _reselect_mavutil_dialect() -> None:
    mavutil = sys.modules.get("pymavlink.mavutil")
    if mavutil is not None and mavutil.mavlink.WIRE_PROTOCOL_VERSION != "2.0":
        mavutil.set_dialect(mavutil.current_dialect)


_reselect_mavutil_dialect()

from .bridge import CommandSink, MavlinkBridge  # noqa: E402
from .protocol import CommandEncoder  # noqa: E402

__all__ = ["CommandEncoder", "CommandSink", "MavlinkBridge"]
