"""Writing a file into an output folder: whole or not at all, and never through a link.

:func:`write_output` writes a temporary file beside the target (created with ``O_EXCL``, which
does not follow links) and renames it over the target: a symbolic link planted where an output
goes is replaced, never followed, and a full disk leaves the old file (or none), not a 0-byte or
half-written one. A failed write is an :class:`OutputError` (a :class:`UserError`, exit 2) that
names the folder; "no space left on OUT" for a full disk or quota.

Spreadsheet safety: :func:`csv_cell` never lets a text cell begin with ``=``, ``+``, ``-``,
``@``, a tab or a carriage return unless it is a plain number: such a cell is prefixed with
``'`` so that a spreadsheet shows it as text instead of running it as a formula.
"""

from __future__ import annotations

import contextlib
import errno
import io
import math
import os
import tempfile
from pathlib import Path

from uavxai.errors import UserError

NO_SPACE = (errno.ENOSPC, errno.EDQUOT)
_FORMULA_START = ("=", "+", "-", "@", "\t", "\r")


class OutputError(UserError):
    """An output file that could not be written; ``folder`` is the output folder."""

    def __init__(self, message: str, folder: Path) -> None:
        super().__init__(message)
        self.folder = folder


def output_error(path: Path, exc: OSError) -> OutputError:
    """The user's message for ``exc`` raised while writing ``path``."""
    folder = Path(path).parent
    if exc.errno in NO_SPACE:
        return OutputError(
            f"no space left on {folder} (writing {Path(path).name}: {exc.strerror or exc}); "
            "free some space or choose another --out. The files already there are whole; the "
            "folder's .uavxai-run marker says it is incomplete.",
            folder,
        )
    return OutputError(
        f"cannot write {path} ({exc.strerror or exc}); the output folder must be writable and "
        "hold no folder or special file where uavxai writes its outputs.",
        folder,
    )


def write_output(path: str | Path, data: str | bytes) -> Path:
    """Write ``data`` to ``path`` atomically (temporary file + rename), never through a link."""
    path = Path(path)
    raw = data.encode("utf-8") if isinstance(data, str) else data
    try:
        fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".part", dir=path.parent)
    except OSError as exc:
        raise output_error(path, exc) from None
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(raw)
        os.chmod(tmp, 0o644)
        if path.is_dir() and not path.is_symlink():
            raise IsADirectoryError(errno.EISDIR, "a folder is in the way", str(path))
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError):
            raise output_error(path, exc) from None
        raise
    return path


def write_figure(path: str | Path, fig, **savefig_kwargs) -> Path:
    """A matplotlib figure written whole (:func:`write_output`), in the format its name
    ends with (``.png``, ``.pdf``)."""
    buf = io.BytesIO()
    fig.savefig(buf, format=Path(path).suffix.lstrip(".") or "png", **savefig_kwargs)
    return write_output(path, buf.getvalue())


def write_torch(path: str | Path, obj: object) -> Path:
    """``torch.save(obj)`` written whole (:func:`write_output`): a checkpoint is never left
    half-written by a full disk or a signal."""
    import torch

    buf = io.BytesIO()
    torch.save(obj, buf)
    return write_output(path, buf.getvalue())


def csv_cell(value):
    """``value`` for a CSV cell, text that a spreadsheet would run as a formula made inert."""
    if isinstance(value, str) and value.startswith(_FORMULA_START):
        try:
            float(value)
        except ValueError:
            return "'" + value
    return value


def cell_number(value) -> float:
    """A results cell as a number: empty or None (a value not defined, which the CSV files
    keep empty) is nan."""
    return math.nan if value is None or value == "" else float(value)
