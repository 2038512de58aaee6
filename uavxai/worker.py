"""An object in its own process: the second core, for work that need not hold up the flight.

JSBSim holds the GIL while it integrates, so a thread cannot work beside it; a process can.
A :class:`Worker` builds ``factory(*args, **kwargs)`` in a spawned process and forwards method
calls to it over a pipe, in the order they were made, so what the object does does not depend
on where it runs:

- :meth:`Worker.call` waits for the answer;
- :meth:`Worker.submit` starts a call and :meth:`Worker.result` collects its answer later
  (the caller flies on meanwhile);
- :meth:`Worker.post` is one-way and batched (a recorder's per-sample logging): the first
  failure among posted calls is raised at the next answer or at :meth:`Worker.close`.

The process is started with ``spawn`` (no fork of a process that holds JSBSim, rerun and
torch threads), ignores Ctrl-C and SIGTERM (the parent handles them and then closes the
worker in order, so a recording interrupted by the user, or by a SIGTERM sent to the whole
process group, is still complete), dies with its parent (even one killed by SIGKILL:
:mod:`uavxai.processes`) and reports a failure by name rather than hanging.
"""

from __future__ import annotations

import contextlib
import multiprocessing as mp
import os
import traceback
from collections.abc import Callable
from multiprocessing.connection import Connection

from uavxai.errors import UserError
from uavxai.processes import die_with_parent, ignore_interrupts

_BATCH = 64  # posted calls per pipe message: one pickle and one write instead of many
_REPLY, _POST = True, False


def _serve(conn: Connection, parent: int, factory: Callable, args: tuple, kwargs: dict) -> None:
    """The worker's loop: build the object, then run batches of calls until told to stop.
    Every answer is ("ok", value) or ("error", text)."""
    die_with_parent(parent)
    ignore_interrupts()
    try:
        obj = factory(*args, **kwargs)
    except Exception as exc:  # noqa: BLE001 - reported to the parent, which raises it
        conn.send(("error", f"{type(exc).__name__}: {exc}"))
        return
    conn.send(("ok", None))
    failed: str | None = None  # the first posted call that failed, not yet reported
    while True:
        try:
            batch = conn.recv()
        except EOFError:
            return
        for method, args, kwargs, reply in batch:
            if method is None:
                # Everything asked of it is done (a recording is flushed and closed by its
                # own close): skip the interpreter's teardown of torch and rerun, which takes
                # longer than the work it would tidy up after (0.4-0.5 s measured).
                conn.close()
                os._exit(0)
            if failed is not None and reply:
                conn.send(("error", failed))
                failed = None
                continue
            try:
                value = getattr(obj, method)(*args, **kwargs) if method else None  # "": sync
            except Exception:  # noqa: BLE001 - as above
                text = f"{method} failed:\n{traceback.format_exc(limit=4)}"
                if reply:
                    conn.send(("error", text))
                else:
                    failed = failed or text
                continue
            if reply:
                conn.send(("ok", value))


class Worker:
    """``factory(*args, **kwargs)`` built and called in its own process (see the module)."""

    def __init__(self, factory: Callable, *args: object, name: str, **kwargs: object) -> None:
        self.name = name
        ctx = mp.get_context("spawn")
        self._conn, child = ctx.Pipe()
        self._proc = ctx.Process(
            target=_serve,
            args=(child, os.getpid(), factory, args, kwargs),
            name=f"uavxai-{name}",
            daemon=True,
        )
        self._proc.start()
        child.close()
        self._posted: list[tuple] = []
        self._started = False  # confirmed at the first answer: start-up overlaps the caller's
        self._waiting = False  # a submitted call whose answer is not collected yet

    def call(self, method: str, *args: object, **kwargs: object) -> object:
        """Run ``method`` there and return its value."""
        self.submit(method, *args, **kwargs)
        return self.result()

    def submit(self, method: str, *args: object, **kwargs: object) -> None:
        """Start ``method`` there; :meth:`result` returns its value."""
        if self._waiting:
            raise RuntimeError(f"the {self.name} worker is still busy; call result() first")
        self._posted.append((method, args, kwargs, _REPLY))
        self._flush()
        self._waiting = True

    def result(self) -> object:
        """The value of the last :meth:`submit`, waiting for it if it is not ready."""
        if not self._waiting:
            raise RuntimeError(f"nothing submitted to the {self.name} worker")
        self._waiting = False
        self._start()
        return self._receive()

    def post(self, method: str, *args: object, **kwargs: object) -> None:
        """Run ``method`` there without waiting for it (or for its value)."""
        self._posted.append((method, args, kwargs, _POST))
        if len(self._posted) >= _BATCH:
            self._flush()

    def flush(self) -> None:
        """Send the posted calls now (a caller whose calls should start at once)."""
        self._flush()

    @property
    def pid(self) -> int | None:
        return self._proc.pid

    def close(self, method: str | None = None) -> None:
        """Run the posted calls and ``method`` (the object's own close, say), then stop the
        process; raises what failed there."""
        try:
            if self._proc.is_alive():
                if self._waiting:
                    self.result()  # an abandoned call: its answer is drained, in order
                self.call(method or "")  # also reports a posted call that failed
        finally:
            self._stop()

    def _stop(self) -> None:
        if self._proc.is_alive():
            with contextlib.suppress(BrokenPipeError, OSError):
                self._conn.send([(None, (), {}, _POST)])
            self._proc.join(timeout=10)
            if self._proc.is_alive():
                self._proc.kill()
        self._conn.close()

    def __enter__(self) -> Worker:
        return self

    def __exit__(self, *exc: object) -> None:
        self._stop()

    def _flush(self) -> None:
        if self._posted:
            try:
                self._conn.send(self._posted)
            except (BrokenPipeError, OSError):
                self._died("run the calls sent to it")
            self._posted = []

    def _start(self) -> None:
        if not self._started:
            self._started = True
            status, value = self._recv("start")
            if status == "error":
                self._proc.join(timeout=5)
                raise UserError(f"the {self.name} could not start: {value}")

    def _receive(self) -> object:
        status, value = self._recv("answer")
        if status == "error":
            raise RuntimeError(f"the {self.name} worker failed: {value}")
        return value

    def _recv(self, what: str) -> tuple[str, object]:
        try:
            return self._conn.recv()
        except EOFError:
            self._died(what)

    def _died(self, what: str):
        self._proc.join(timeout=5)
        raise RuntimeError(
            f"the {self.name} process ended (exit code {self._proc.exitcode}) before it could "
            f"{what}. It is started with multiprocessing's 'spawn', which imports the main "
            "script again: a script that flies `uavxai run` episodes from Python must keep its "
            'top level under `if __name__ == "__main__":`'
        ) from None
