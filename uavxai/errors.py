"""User-facing errors.

Anything the user can fix (a bad scenario, a bad flag, a missing checkpoint, an existing output
folder) raises :class:`UserError`; the CLI prints its message and exits 2 without a traceback.
Everything else is an internal error (exit 1).
"""

from __future__ import annotations

import reprlib
from typing import Any

# Error messages quote what a hostile file holds: reprlib stops after a few items and levels,
# so a value built from a billion aliases costs as little to show as a small one.
_SHORT = reprlib.Repr()  # Python 3.11: no keyword arguments yet
_SHORT.maxlevel, _SHORT.maxtuple, _SHORT.maxlist, _SHORT.maxdict = 2, 4, 4, 4
_SHORT.maxstring, _SHORT.maxlong, _SHORT.maxother = 40, 40, 40


def short_repr(value: Any) -> str:
    """A bounded repr of ``value`` for an error message."""
    return _SHORT.repr(value)


class UserError(Exception):
    """Bad input: the message names what is wrong and what is allowed."""


class ScenarioError(UserError):
    """A scenario file that cannot be read or does not validate."""


class CheckpointError(UserError):
    """A missing, unreadable or mismatched model checkpoint."""
