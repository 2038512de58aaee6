"""Fixtures shared by test files."""

from __future__ import annotations

import pytest

from uavxai import cli


@pytest.fixture
def release_cli_locks():
    """prepare_out_dir keeps its output folder's lock for the life of the process; the tests
    that call the command line end it themselves after each test."""
    yield
    for lock in cli._HELD_LOCKS.values():
        lock.close()
    cli._HELD_LOCKS.clear()
