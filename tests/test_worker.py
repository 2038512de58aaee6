"""An object in its own process (uavxai.worker.Worker): calls in order, failures by name."""

from __future__ import annotations

import os
import signal
import time

import pytest

from uavxai.errors import UserError
from uavxai.worker import Worker


def test_calls_run_in_another_process_in_the_order_they_were_made() -> None:
    with Worker(list, name="test list") as w:
        assert w.pid is not None and w.pid != os.getpid()
        for i in range(200):  # more than one batch of posts
            w.post("append", i)
        w.submit("copy")
        assert w.result() == list(range(200))
        w.post("clear")
        assert w.call("copy") == []


def test_a_posted_call_that_fails_is_reported_at_the_next_answer_and_the_worker_goes_on() -> None:
    with Worker(list, name="test list") as w:
        w.post("remove", 99)  # ValueError there, nothing here yet
        w.post("append", 1)
        with pytest.raises(RuntimeError, match="the test list worker failed: remove failed"):
            w.call("copy")
        assert w.call("copy") == [1]  # reported once; the calls after it ran
        with pytest.raises(RuntimeError, match="pop failed"):
            w.call("pop", 5)


def test_close_reports_a_failed_posted_call() -> None:
    w = Worker(list, name="test list")
    w.post("index", "missing")
    with pytest.raises(RuntimeError, match="index failed"):
        w.close()
    assert w.pid is not None
    with pytest.raises(ProcessLookupError):
        os.kill(w.pid, 0)  # stopped, whatever failed


def test_an_object_that_cannot_be_built_is_a_user_error_naming_the_worker() -> None:
    with (
        Worker(int, "not a number", name="test int") as w,
        pytest.raises(UserError, match="the test int could not start: ValueError"),
    ):
        w.call("bit_length")


def test_ctrl_c_is_the_parent_s_to_handle() -> None:
    """Ctrl-C reaches the whole process group; the worker ignores it so that the parent can
    close it in order (a recording interrupted by the user is still complete)."""
    with Worker(list, name="test list") as w:
        w.call("append", 1)
        os.kill(w.pid, signal.SIGINT)
        time.sleep(0.2)
        assert w.call("copy") == [1]


def test_misuse_is_named() -> None:
    with Worker(list, name="test list") as w:
        with pytest.raises(RuntimeError, match="nothing submitted"):
            w.result()
        w.submit("copy")
        with pytest.raises(RuntimeError, match="still busy"):
            w.submit("copy")
        assert w.result() == []
