"""Loading a service-point checkpoint without trusting it (issue 30).

A checkpoint is data: its declared sizes are checked against bounds, then the network they
describe is built on torch's ``meta`` device (shapes only, no memory) and its state-dict shapes
compared with the stored tensors, and the tensors must be finite, all before a real network is
allocated. So a 1.5 kB file cannot ask for gigabytes, and an all-NaN model is refused instead
of planning with objective 0. The same bounds as the avoidance checkpoints
(:mod:`uavxai.avoidance.learned`).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import torch
from torch import nn

from uavxai.errors import CheckpointError, short_repr

MAX_CHECKPOINT_BYTES = 256 * 2**20
MAX_HIDDEN_WIDTH = 4096
MAX_LAYERS = 8
MAX_OBS_DIM = 4096
MAX_USERS = 64
MAX_POWER_LEVELS = 64



def read_checkpoint(p: Path, where: str, remedy: str) -> Any:
    """``torch.load`` (weights only) of a file no bigger than :data:`MAX_CHECKPOINT_BYTES`."""
    try:
        size = p.stat().st_size
    except FileNotFoundError:
        raise CheckpointError(f"{where} {p}: no such file. {remedy}") from None
    except OSError as exc:
        raise CheckpointError(f"{where} {p}: cannot read it ({exc.strerror}). {remedy}") from None
    if size > MAX_CHECKPOINT_BYTES:
        raise CheckpointError(
            f"{where} {p}: {size} bytes; allowed: at most {MAX_CHECKPOINT_BYTES} bytes. {remedy}"
        )
    try:
        return torch.load(p, map_location="cpu", weights_only=True)
    except Exception as exc:  # noqa: BLE001 - torch raises many types for a bad file
        raise CheckpointError(
            f"{where} {p}: not a readable model file ({type(exc).__name__}). {remedy}"
        ) from None


def declared_int(data: dict, field: str, lo: int, hi: int, p: Path, where: str, remedy: str) -> int:
    value = data.get(field)
    if not (isinstance(value, int) and not isinstance(value, bool) and lo <= value <= hi):
        raise CheckpointError(
            f"{where} {p}: {field} = {short_repr(value)}; allowed: an integer from {lo} to "
            f"{hi}. {remedy}"
        )
    return value


def declared_bool(data: dict, field: str, p: Path, where: str, remedy: str) -> bool:
    value = data.get(field)
    if not isinstance(value, bool):
        raise CheckpointError(
            f"{where} {p}: {field} = {short_repr(value)}; allowed: true or false. {remedy}"
        )
    return value


def build_checked(
    factory: Callable[[], nn.Module], state_dict: Any, p: Path, where: str, remedy: str
) -> nn.Module:
    """``factory()`` loaded with ``state_dict``, once the stored tensors are known to have
    exactly the shapes of that network (compared on the ``meta`` device, allocating nothing)
    and to be finite floating-point numbers."""
    if not isinstance(state_dict, dict):
        raise CheckpointError(f"{where} {p}: state_dict is missing or not a mapping. {remedy}")
    with torch.device("meta"):
        shape_only = factory()
    expected = {k: tuple(v.shape) for k, v in shape_only.state_dict().items()}
    found = {
        k: tuple(v.shape) if isinstance(v, torch.Tensor) else type(v).__name__
        for k, v in state_dict.items()
    }
    if found != expected:
        wrong = sorted(set(found.items()) ^ set(expected.items()), key=str)[:4]
        raise CheckpointError(
            f"{where} {p}: the stored weights do not have the declared sizes (differs at "
            f"{short_repr(wrong)}); the file is damaged or forged. {remedy}"
        )
    for k, v in state_dict.items():
        if not v.is_floating_point() or not bool(torch.isfinite(v).all()):
            what = "non-finite values (NaN or inf)" if v.is_floating_point() else str(v.dtype)
            raise CheckpointError(
                f"{where} {p}: tensor '{k}' holds {what}; allowed: finite floating-point "
                f"weights. {remedy}"
            )
    net = factory()
    net.load_state_dict(state_dict)
    return net.eval()
