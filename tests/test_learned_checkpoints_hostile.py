"""Hostile avoidance checkpoints (issue 14): declared sizes are not trusted, NaN or bit-flipped
weights are refused, and malformed metadata is a CheckpointError (a UserError: exit 2) naming
the file, the field and what is allowed."""

from __future__ import annotations

import resource
import zipfile
from pathlib import Path

import numpy as np
import pytest
import torch

from uavxai.avoidance.learned import (
    QNetwork,
    load_checkpoint,
    obs_dim,
    save_checkpoint,
)
from uavxai.cli import main
from uavxai.errors import CheckpointError, UserError
from uavxai.learning.checkpoint import MAX_CHECKPOINT_BYTES, MAX_HIDDEN_WIDTH

N_NEAREST, HIDDEN = 4, (16,)


@pytest.fixture
def good(tmp_path: Path) -> Path:
    path = tmp_path / "good.pt"
    torch.manual_seed(0)
    nets = {"q": QNetwork(obs_dim(N_NEAREST), HIDDEN)}
    save_checkpoint(path, "dqn", nets, hidden=HIDDEN, n_nearest=N_NEAREST, meta={"note": "ok"})
    return path


def tampered(good: Path, tmp_path: Path, change) -> Path:
    """A copy of ``good`` whose loaded dict ``change`` edited, written as torch.save would."""
    ckpt = torch.load(good, weights_only=True)
    change(ckpt)
    path = tmp_path / "tampered.pt"
    torch.save(ckpt, path)
    return path


def refused(path: Path, *words: str) -> str:
    with pytest.raises(CheckpointError) as err:
        load_checkpoint(path, "dqn")
    message = str(err.value)
    assert isinstance(err.value, UserError)
    assert str(path) in message, message
    for word in words:
        assert word in message, message
    assert len(message) < 600, message  # a hostile value is not printed whole
    return message


def peak_rss_mib() -> float:
    return resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024  # Linux: KiB


def test_the_good_checkpoint_loads(good: Path) -> None:
    nets, info = load_checkpoint(good, "dqn")
    assert info["hidden"] == [16] and info["n_nearest"] == N_NEAREST and info["note"] == "ok"
    out = nets["q"](torch.zeros(1, obs_dim(N_NEAREST)))
    assert out.shape == (1, 9) and bool(torch.isfinite(out).all())


def test_hidden_layers_of_60000_are_refused_before_anything_is_allocated(good, tmp_path) -> None:
    """Issue 14: a checkpoint declaring hidden layers of 60000 allocated over 8 GB (two
    60000-wide layers are 14 GB of float32) before its shape was checked."""
    path = tampered(good, tmp_path, lambda c: c.update(hidden=[60000, 60000]))
    before = peak_rss_mib()
    refused(path, "hidden", "[60000, 60000]", f"from 1 to {MAX_HIDDEN_WIDTH}")
    assert peak_rss_mib() - before < 100  # nothing near the declared size was ever touched


def test_declared_sizes_must_match_the_stored_tensors(good, tmp_path) -> None:
    # within the bounds, but not what the tensors are: refused before building the network
    path = tampered(good, tmp_path, lambda c: c.update(hidden=[4000, 4000]))
    before = peak_rss_mib()
    refused(path, "wrong shape", "hidden [4000, 4000]")
    assert peak_rss_mib() - before < 30  # 4000 x 4000 float32 would be 61 MiB per layer


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_weights_are_refused(good, tmp_path, value) -> None:
    def poison(c):
        c["state_dicts"]["q"]["net.2.weight"][3, 5] = value

    refused(tampered(good, tmp_path, poison), "net.2.weight", "non-finite", "finite")


def test_a_bit_flipped_checkpoint_is_refused(good, tmp_path) -> None:
    """torch.load reads a flipped bit in a tensor silently; the zip record's CRC does not."""
    with zipfile.ZipFile(good) as archive:
        record = next(r for r in archive.infolist() if r.filename.endswith("/data/1"))
    data = bytearray(good.read_bytes())
    # The record's data follows its 30-byte local header, name and extra field.
    at = record.header_offset
    name_len = int.from_bytes(data[at + 26 : at + 28], "little")
    extra_len = int.from_bytes(data[at + 28 : at + 30], "little")
    start = at + 30 + name_len + extra_len
    flipped = tmp_path / "flipped.pt"
    data[start + 17] ^= 0x04
    flipped.write_bytes(bytes(data))
    # what the old loader did: no complaint, other weights
    flipped_w = torch.load(flipped, weights_only=True)["state_dicts"]["q"]["net.0.weight"]
    good_w = torch.load(good, weights_only=True)["state_dicts"]["q"]["net.0.weight"]
    assert not torch.equal(flipped_w, good_w)
    refused(flipped, "damaged", "CRC")


@pytest.mark.parametrize(
    ("field", "value", "words"),
    [
        ("n_nearest", "eight", ("n_nearest", "an integer from 1 to")),
        ("n_nearest", 10**9, ("n_nearest", "an integer from 1 to")),
        ("n_nearest", True, ("n_nearest",)),
        ("n_nearest", None, ("n_nearest",)),
        ("hidden", "16", ("hidden", "layer widths")),
        ("hidden", [], ("hidden",)),
        ("hidden", [16.0], ("hidden",)),
        ("hidden", [-16], ("hidden",)),
        ("hidden", [16] * 9, ("hidden", "1 to 8")),
        ("hidden", list(range(1, 10**5)), ("hidden",)),
        ("meta", ["not", "a", "mapping"], ("meta", "mapping")),
        ("meta", {1: "x"}, ("meta",)),
        ("state_dicts", [1, 2], ("state_dicts",)),
        ("state_dicts", {}, ("network 'q' is missing",)),
        ("state_dicts", {"q": {"net.0.weight": "w"}}, ("wrong shape",)),
        ("obs_probe", "x" * 10**6, ("observation that differs",)),
        ("obs_probe", torch.zeros(10**3), ("observation that differs",)),
        ("obs_dim", 10**12, ("observation that differs",)),
        ("algo", "x" * 10**6, ("trained for",)),
        ("format", ["x"] * 10**6, ("not an avoidance checkpoint",)),
    ],
)
def test_malformed_metadata_names_the_file_the_field_and_what_is_allowed(
    good, tmp_path, field, value, words
) -> None:
    refused(tampered(good, tmp_path, lambda c: c.update({field: value})), *words)


def test_missing_metadata_and_extra_tensors_are_refused(good, tmp_path) -> None:
    refused(tampered(good, tmp_path, lambda c: c.pop("hidden")), "hidden")

    def extra(c):
        c["state_dicts"]["q"]["net.9.weight"] = torch.zeros(2, 2)

    refused(tampered(good, tmp_path, extra), "wrong shape", "net.9.weight")

    def integer(c):
        c["state_dicts"]["q"]["net.0.bias"] = torch.zeros(16, dtype=torch.int64)

    refused(tampered(good, tmp_path, integer), "net.0.bias", "torch.int64")


def test_oversized_and_foreign_files_are_refused(good, tmp_path) -> None:
    big = tmp_path / "big.pt"
    with open(big, "wb") as f:  # sparse: no disk or memory is used for it
        f.truncate(MAX_CHECKPOINT_BYTES + 1)
    refused(big, "bytes", "at most")
    legacy = tmp_path / "legacy.pt"
    torch.save(torch.load(good, weights_only=True), legacy, _use_new_zipfile_serialization=False)
    refused(legacy, "not a readable torch checkpoint")
    rng = np.random.default_rng(14)
    noise = tmp_path / "noise.pt"
    noise.write_bytes(b"PK\x03\x04" + rng.bytes(4000))
    refused(noise, "not a readable torch checkpoint")


def test_a_hostile_checkpoint_exits_2_through_the_cli(good, tmp_path, capsys) -> None:
    path = tampered(good, tmp_path, lambda c: c.update(hidden=[60000, 60000]))
    scenario = tmp_path / "s.yaml"
    scenario.write_text(
        f"name: s\nintruders: {{count: 2}}\navoidance: {{planner: dqn, checkpoint: {path}}}\n"
    )
    code = main(
        ["evaluate", str(scenario), "--methods", "dqn", "--intruders", "2", "--episodes", "1",
         "--out", str(tmp_path / "out")]
    )  # fmt: skip
    err = capsys.readouterr().err
    assert code == 2, err
    assert str(path) in err and "hidden" in err and "Traceback" not in err


def test_fuzzed_checkpoint_files_load_unchanged_or_are_refused(good, tmp_path) -> None:
    """Random bytes flipped anywhere in the file, or the file cut short: the loader either
    refuses it with a CheckpointError or returns exactly the original weights (a flip in the
    zip padding changes nothing), never other weights and never another exception."""
    rng = np.random.default_rng(1414)
    original = good.read_bytes()
    reference = {k: v.clone() for k, v in load_checkpoint(good, "dqn")[0]["q"].state_dict().items()}
    mutant = tmp_path / "mutant.pt"
    outcomes = {"refused": 0, "unchanged": 0}
    for trial in range(300):
        data = bytearray(original)
        if trial % 5 == 4:
            data = data[: int(rng.integers(0, len(data)))]
        else:
            for at in rng.integers(0, len(data), int(rng.integers(1, 5))):
                data[at] ^= int(rng.integers(1, 256))
        mutant.write_bytes(bytes(data))
        try:
            nets, _ = load_checkpoint(mutant, "dqn")
        except CheckpointError as err:
            assert str(mutant) in str(err)
            outcomes["refused"] += 1
            continue
        loaded = nets["q"].state_dict()
        assert all(torch.equal(loaded[k], reference[k]) for k in reference), trial
        outcomes["unchanged"] += 1
    assert outcomes["refused"] > 200
