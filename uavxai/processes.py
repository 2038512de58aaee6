"""How uavxai's processes end: together, and never in the middle of writing their outputs.

- :func:`die_with_parent`, called first thing in a child process (a :class:`~uavxai.worker.Worker`,
  a campaign's pool worker, the pool's forkserver): the child gets SIGKILL when its parent
  ends, even by SIGKILL (Linux ``prctl(PR_SET_PDEATHSIG)``), so a killed uavxai leaves no
  process behind. The pool's workers are children of multiprocessing's forkserver, which is a
  child of uavxai: each dies with its own parent (:mod:`uavxai.forkserver_preload`), and
  multiprocessing's resource tracker then ends by itself when the last of them is gone.
  The kernel sends the signal when the *thread* that started the child ends: uavxai starts
  its children from the main thread.
- :func:`ignore_interrupts`: a child leaves SIGINT and SIGTERM to its parent, which closes or
  kills it in order (a Ctrl-C or a SIGTERM sent to the whole process group does not kill a
  recorder before the run has closed its recording).
- :func:`raise_on_interrupt`: the command line's SIGINT and SIGTERM, a ``KeyboardInterrupt``
  (the command stops and saves what it has), once.
- :func:`interrupts_deferred`: while outputs are saved, SIGINT and SIGTERM are noted, not
  raised; the save ends whole and the signal is delivered after it.
"""

from __future__ import annotations

import contextlib
import ctypes
import os
import signal
import sys
import threading
from collections.abc import Iterator

_PR_SET_PDEATHSIG = 1  # <linux/prctl.h>
_INTERRUPTS = (signal.SIGINT, signal.SIGTERM)


def die_with_parent(parent: int | None) -> None:
    """Have this process killed when its parent ends; ``parent``, the pid the parent had when
    it started this one (None: unknown). If that parent has already ended (it died before the
    request could be made), end now."""
    if sys.platform.startswith("linux"):
        with contextlib.suppress(OSError, AttributeError):
            libc = ctypes.CDLL(None, use_errno=True)
            libc.prctl(_PR_SET_PDEATHSIG, signal.SIGKILL, 0, 0, 0)
    # Checked after the request: a parent that died before it was made has handed this
    # process to another one already, and would never send the signal.
    if parent is not None and os.getppid() != parent:
        os._exit(1)


def raise_on_interrupt(once: bool) -> None:
    """SIGINT and SIGTERM raise ``KeyboardInterrupt`` in the main thread: the command stops
    and saves what it has. ``once``: only the first one does and later ones are ignored, for
    the process is ending already (the program; a caller in Python keeps its own Ctrl-C)."""

    def interrupt(signum: int, frame: object) -> None:
        if once:
            ignore_interrupts()  # before raising: nothing can come between
        raise KeyboardInterrupt(f"signal {signum}")

    if threading.current_thread() is threading.main_thread():
        for sig in _INTERRUPTS:
            signal.signal(sig, interrupt)


def ignore_interrupts() -> None:
    """SIGINT and SIGTERM ignored: in a child, whose parent handles them and stops it
    itself; in the program, once it is ending."""
    for sig in _INTERRUPTS:
        signal.signal(sig, signal.SIG_IGN)


@contextlib.contextmanager
def restored_interrupts() -> Iterator[None]:
    """The SIGINT and SIGTERM handlers in place before the body, put back after it (main
    thread only: elsewhere nothing can change them)."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    previous = {sig: signal.getsignal(sig) for sig in _INTERRUPTS}
    try:
        yield
    finally:
        for sig, handler in previous.items():  # None: a handler not set from Python
            signal.signal(sig, signal.SIG_DFL if handler is None else handler)


@contextlib.contextmanager
def interrupts_deferred(deliver: bool = True) -> Iterator[list[int]]:
    """SIGINT and SIGTERM noted, not raised, while the body runs (a save that must end
    whole); at its end the first that came is sent again if ``deliver`` (False: the caller
    is already ending for an interruption, and a second one changes nothing). Yields the list
    of the signals that came. Outside the main thread signals cannot be handled, and nothing
    changes."""
    caught: list[int] = []
    if threading.current_thread() is not threading.main_thread():
        yield caught
        return

    def note(signum: int, frame: object) -> None:
        caught.append(signum)

    with restored_interrupts():
        for sig in _INTERRUPTS:
            signal.signal(sig, note)
        yield caught
    if caught and deliver:
        # sent again, to the handler now in place: what it does with a signal it does now
        signal.raise_signal(caught[0])

