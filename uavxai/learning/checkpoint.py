"""The one checkpoint module: how every learned planner's weights are written and read back
without trusting the file (issues 14, 29, 30).

Three kinds of model travel in checkpoints, each in its own layout (the shipped files are of
these layouts and load unchanged): the avoidance Q-networks (DQN, Safe-DQN:
:mod:`uavxai.avoidance.learned`), the branching service-point network of one layout
(:mod:`uavxai.service.d3qn`) and the universal set network (:mod:`uavxai.service.universal`).
Each is a ``torch.save`` of a dict holding a ``format`` tag (:data:`FORMATS`), the sizes the
network is rebuilt from, its state dict(s) and what it was trained on.

Reading is the same for all of them: the file's size and its zip archive's record count are
bounded and every record's CRC checked (torch's loader reads a bit-flipped tensor without a
word), the dict is loaded with ``weights_only=True`` (no code runs), the tag must be the
kind's, every declared size is an integer within the bounds below, and the network those sizes
describe is built on torch's ``meta`` device (shapes only, no memory) and compared with the
stored tensors, which must be finite, before a real network is allocated. So a 1.5 kB file
cannot ask for gigabytes and an all-NaN model is refused instead of flown. Every problem is a
:class:`~uavxai.errors.CheckpointError` (exit 2) naming the file, the field and what is
allowed.

Inference code (``avoidance/``, ``service/``) reads with this module, so it sits low in the
layers (pyproject.toml): it imports nothing of uavxai but the errors and the output writer.
"""

from __future__ import annotations

import zipfile
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import torch
from torch import nn

from uavxai.errors import CheckpointError, short_repr
from uavxai.outputs import write_torch

# kind -> (format tag in the file, what the file is in words)
FORMATS = {
    "avoidance": ("uavxai-avoidance-qnet", "an avoidance checkpoint"),
    "branching": ("uavxai.service.branching-q/1", "a uavxai service-point model"),
    "universal": ("uavxai.service.universal-q/1", "a uavxai universal service model"),
}

# Bounds on what a checkpoint may declare, checked before anything is allocated from it: a file
# is data, and its sizes are not to be trusted (issue 14: hidden layers of 60000 asked for over
# 8 GB before any shape was compared). Generous next to what training writes.
MAX_CHECKPOINT_BYTES = 256 * 2**20
MAX_CHECKPOINT_RECORDS = 1000
MAX_HIDDEN_WIDTH = 4096
MAX_LAYERS = 8
MAX_OBS_DIM = 4096
MAX_USERS = 64
MAX_POWER_LEVELS = 64
MAX_N_NEAREST = 64


@dataclass(frozen=True)
class Source:
    """A checkpoint file, where it was named (``avoidance.checkpoint``, ``service model`` ...)
    and what to do about a bad one, so that every error names the file and the remedy alike."""

    path: Path
    where: str
    remedy: str

    def error(self, text: str) -> CheckpointError:
        return CheckpointError(f"{self.where} {self.path}: {text} {self.remedy}")

    def bad(self, field: str, value: object, allowed: str) -> CheckpointError:
        """The error for a declared field outside what this uavxai can load."""
        return self.error(f"{field} = {short_repr(value)}; allowed: {allowed}.")


def save(path: Path, kind: str, fields: dict[str, Any]) -> Path:
    """Write a checkpoint of ``kind`` (sizes, state dicts, meta in ``fields``), whole or not
    at all (:func:`~uavxai.outputs.write_torch`): loadable with ``weights_only=True``."""
    return write_torch(path, {"format": FORMATS[kind][0], **fields})


def read(src: Source, kind: str) -> dict[str, Any]:
    """The checkpoint dict of ``src``, once the file is a readable, intact ``kind`` one.
    Nothing in it is trusted yet: check its sizes with :func:`declared_int` and its weights
    with :func:`build_checked`."""
    _check_archive(src)
    try:
        data = torch.load(src.path, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for a bad file
        raise src.error(f"not a readable torch checkpoint ({type(exc).__name__}).") from None
    tag, what = FORMATS[kind]
    if not isinstance(data, dict) or data.get("format") != tag:
        found = short_repr(data.get("format")) if isinstance(data, dict) else type(data).__name__
        raise src.error(f"not {what} (format {found}, expected {tag}).")
    return data


def _check_archive(src: Source) -> None:
    """Bounded size, and every record's CRC (torch.save writes a zip archive that keeps a
    CRC-32 of every record)."""
    try:
        size = src.path.stat().st_size
    except FileNotFoundError:
        raise src.error("no such file.") from None
    except OSError as exc:
        raise src.error(f"cannot read it ({exc.strerror}).") from None
    if size > MAX_CHECKPOINT_BYTES:
        raise src.error(f"{size} bytes; allowed: at most {MAX_CHECKPOINT_BYTES} bytes.")
    try:
        with zipfile.ZipFile(src.path) as archive:
            records = archive.infolist()
            declared = sum(r.file_size for r in records)
            if len(records) > MAX_CHECKPOINT_RECORDS or declared > MAX_CHECKPOINT_BYTES:
                raise src.error(
                    f"declares {len(records)} records of {declared} bytes; allowed: at most "
                    f"{MAX_CHECKPOINT_RECORDS} records and {MAX_CHECKPOINT_BYTES} bytes."
                )
            damaged = archive.testzip()
    except CheckpointError:
        raise
    except Exception as exc:  # noqa: BLE001 - not a zip, or one too broken to list
        raise src.error(f"not a readable torch checkpoint ({type(exc).__name__}).") from None
    if damaged is not None:
        raise src.error(
            f"damaged (record '{short_repr(damaged)}' fails its CRC check): the file changed "
            "after it was written; copy it again or retrain."
        )


def is_int(value: object) -> bool:
    return isinstance(value, int) and not isinstance(value, bool)


def declared_int(data: dict, field: str, lo: int, hi: int, src: Source) -> int:
    """The integer ``data[field]``, refused unless it is one from ``lo`` to ``hi``."""
    value = data.get(field)
    if not (is_int(value) and lo <= value <= hi):
        raise src.bad(field, value, f"an integer from {lo} to {hi}")
    return value


def declared_bool(data: dict, field: str, src: Source) -> bool:
    value = data.get(field)
    if not isinstance(value, bool):
        raise src.bad(field, value, "true or false")
    return value


def declared_meta(data: dict, src: Source) -> dict:
    """``data["meta"]`` (what the model was trained on): a mapping from names, {} if absent."""
    meta = data.get("meta", {})
    if not isinstance(meta, dict) or not all(isinstance(k, str) for k in meta):
        raise src.bad("meta", meta, "a mapping from names to values")
    return meta


def build_checked(
    factory: Callable[[], nn.Module],
    state_dict: Any,
    src: Source,
    name: str = "model",
    sizes: str = "its declared sizes",
) -> nn.Module:
    """``factory()`` in eval mode loaded with ``state_dict``, once the stored tensors are
    known to have exactly the shapes of that network (compared on the ``meta`` device,
    allocating nothing) and to be finite floating-point numbers. ``name`` names the network
    in errors (a checkpoint may hold several), ``sizes`` the declared sizes in words."""
    if not isinstance(state_dict, dict):
        raise src.error(f"network '{name}' is missing (no state dict).")
    with torch.device("meta"):
        shape_only = factory()
    expected = {k: tuple(v.shape) for k, v in shape_only.state_dict().items()}
    found = {
        k: tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
        for k, v in state_dict.items()
    }
    if found != expected:
        wrong = sorted(set(found.items()) ^ set(expected.items()), key=str)[:4]
        raise src.error(
            f"network '{name}' has the wrong shape for {sizes}: the stored weights do not have "
            f"the declared sizes (differs at {short_repr(wrong)}); the file is damaged or forged."
        )
    for k, v in state_dict.items():
        if not v.is_floating_point() or not bool(torch.isfinite(v).all()):
            what = "non-finite values (NaN or inf)" if v.is_floating_point() else str(v.dtype)
            raise src.error(
                f"network '{name}' tensor '{k}' holds {what}; allowed: finite floating-point "
                "weights. The file is damaged."
            )
    net = factory()
    net.load_state_dict(state_dict)
    return net.eval()
