"""Imported by the forkserver of a campaign's worker pool as it starts (its "preload"): it
dies with the uavxai process that started it, and leaves SIGINT and SIGTERM to that process.

Its workers are forked from it and die with it in turn (``_init_pool_worker`` in
:mod:`uavxai.campaign.runner`); they find its pid in ``FORKSERVER_PID``.

The owner's pid travels in ``STARTED_BY``, in the environment only while :func:`start` starts
the forkserver, which takes it out of its own at once: a process that inherited it (a
``uavxai evaluate`` started by a test runner that had flown a campaign in-process) would
otherwise take itself for a forkserver and ignore SIGTERM (issue 30).
"""

from __future__ import annotations

import os
from multiprocessing import forkserver
from multiprocessing.context import BaseContext

from uavxai.processes import die_with_parent, ignore_interrupts

STARTED_BY = "UAVXAI_FORKSERVER_STARTED_BY"  # set by the pool's owner while it starts it
FORKSERVER_PID = "UAVXAI_FORKSERVER_PID"  # set here, for the workers forked from here


def start(context: BaseContext) -> None:
    """Start this process's forkserver now (once per process; a running one is kept), with
    this module as its preload: it dies with this process, and so its workers too."""
    os.environ[STARTED_BY] = str(os.getpid())
    try:
        context.set_forkserver_preload(["__main__", __name__])
        forkserver.ensure_running()
    finally:
        del os.environ[STARTED_BY]


_owner = os.environ.pop(STARTED_BY, "")
if _owner.isdigit():
    die_with_parent(int(_owner))
    ignore_interrupts()
    os.environ[FORKSERVER_PID] = str(os.getpid())
