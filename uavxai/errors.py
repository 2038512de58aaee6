"""User-facing errors.

Anything the user can fix (a bad scenario, a bad flag, a missing checkpoint, an existing output
folder) raises :class:`UserError`; the CLI prints its message and exits 2 without a traceback.
Everything else is an internal error (exit 1).
"""

from __future__ import annotations


class UserError(Exception):
    """Bad input: the message names what is wrong and what is allowed."""


class ScenarioError(UserError):
    """A scenario file that cannot be read or does not validate."""


class CheckpointError(UserError):
    """A missing, unreadable or mismatched model checkpoint."""
