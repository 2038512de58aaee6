"""Imported by the forkserver of a campaign's worker pool as it starts (its "preload"): it
dies with the uavxai process that started it, and leaves SIGINT and SIGTERM to that process.

Its workers are forked from it and die with it in turn (``_init_pool_worker`` in
:mod:`uavxai.campaign`); they find its pid in ``FORKSERVER_PID``.
"""

from __future__ import annotations

import os

from uavxai.processes import die_with_parent, ignore_interrupts

STARTED_BY = "UAVXAI_FORKSERVER_STARTED_BY"  # set by the pool's owner before it starts
FORKSERVER_PID = "UAVXAI_FORKSERVER_PID"  # set here, for the workers forked from here

if os.environ.get(STARTED_BY, "").isdigit():
    die_with_parent(int(os.environ[STARTED_BY]))
    ignore_interrupts()
    os.environ[FORKSERVER_PID] = str(os.getpid())
