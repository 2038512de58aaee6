"""One checkpoint module reads every kind of model (issue 29): the shipped files of each kind
load through it and give exactly the Q-values of their stored weights, and it refuses what is
not a checkpoint of the kind asked for."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
import torch

from uavxai.avoidance.learned import ALGOS, QNetwork, load_checkpoint, shipped_checkpoint
from uavxai.errors import CheckpointError
from uavxai.learning import checkpoint
from uavxai.learning.replay import ReplayBuffer, n_step_return
from uavxai.service import universal


@pytest.mark.parametrize("algo", ALGOS)
def test_shipped_avoidance_models_give_the_q_values_of_their_stored_weights(algo: str) -> None:
    raw = torch.load(shipped_checkpoint(algo), weights_only=True)
    nets, info = load_checkpoint(None, algo)
    x = torch.as_tensor(
        np.random.default_rng(29).normal(size=(64, raw["obs_dim"])), dtype=torch.float32
    )
    for name, sd in raw["state_dicts"].items():
        bare = QNetwork(raw["obs_dim"], raw["hidden"])
        bare.load_state_dict(sd)
        with torch.no_grad():
            assert torch.equal(nets[name](x), bare(x)), name
    assert info["hidden"] == raw["hidden"]


@pytest.mark.parametrize("algo", ["d3qn", "dqn"])
def test_shipped_universal_models_give_the_q_values_of_their_stored_weights(algo: str) -> None:
    path = universal.shipped_path(algo)
    raw = torch.load(path, weights_only=True)
    net, info = universal.load(path)
    bare = universal.SetQNetwork(raw["power_levels"], raw["hidden"], raw["dueling"])
    bare.load_state_dict(raw["state_dict"])
    bare.eval()
    rng = np.random.default_rng(29)
    glob = torch.as_tensor(rng.normal(size=(8, universal.GLOBAL_FEATURES)), dtype=torch.float32)
    users = torch.as_tensor(rng.normal(size=(8, 5, universal.USER_FEATURES)), dtype=torch.float32)
    mask = torch.ones(8, 5, dtype=torch.bool)
    with torch.no_grad():
        for a, b in zip(net(glob, users, mask), bare(glob, users, mask), strict=True):
            assert torch.equal(a, b)
    assert info["algo"] == algo


def test_a_checkpoint_of_another_kind_is_refused_by_name(tmp_path: Path) -> None:
    src = checkpoint.Source(shipped_checkpoint("dqn"), "service model", "Use another.")
    with pytest.raises(CheckpointError, match="not a uavxai universal service model .*Use another"):
        checkpoint.read(src, "universal")
    with pytest.raises(CheckpointError, match="service model .*nope.pt: no such file"):
        checkpoint.read(checkpoint.Source(tmp_path / "nope.pt", "service model", ""), "universal")


def test_the_replay_buffer_keeps_the_last_transitions_and_samples_only_stored_ones() -> None:
    rb = ReplayBuffer(3, {"obs": ((2,), np.float32), "reward": ((), np.float32)})
    with pytest.raises(ValueError, match="empty"):
        rb.sample(np.random.default_rng(0), 1)
    for i in range(5):
        rb.add(obs=np.array([i, -i]), reward=float(i))
    assert len(rb) == 3 and sorted(rb.data["reward"].tolist()) == [2.0, 3.0, 4.0]
    batch = rb.sample(np.random.default_rng(0), 50)
    assert set(batch["reward"].tolist()) <= {2.0, 3.0, 4.0}
    assert torch.equal(
        batch["obs"][:, 0], batch["reward"]
    )  # fields of one transition stay together
    with pytest.raises(ValueError, match="fields"):
        rb.add(obs=np.zeros(2))


def test_n_step_return_discounts_each_part() -> None:
    ret = n_step_return([(1.0, -1.0), (1.0, 0.0), (0.0, 2.0)], 0.5)
    np.testing.assert_allclose(ret, [1.5, -0.5])


def test_a_bit_flipped_service_model_is_refused_as_the_avoidance_ones_are(tmp_path: Path) -> None:
    """The one reader checks every record's CRC for every kind: a flipped bit in a shipped
    universal model's weights (which torch.load reads without a word) is refused."""
    import zipfile

    shipped = universal.shipped_path("d3qn")
    with zipfile.ZipFile(shipped) as archive:
        record = next(r for r in archive.infolist() if r.filename.endswith("/data/0"))
    data = bytearray(shipped.read_bytes())
    at = record.header_offset  # the data follows the 30-byte local header, name and extra
    start = at + 30 + int.from_bytes(data[at + 26 : at + 28], "little")
    start += int.from_bytes(data[at + 28 : at + 30], "little")
    data[start + 17] ^= 0x04
    flipped = tmp_path / "flipped.pt"
    flipped.write_bytes(bytes(data))
    good = torch.load(shipped, weights_only=True)["state_dict"]
    bad = torch.load(flipped, weights_only=True)["state_dict"]
    assert any(not torch.equal(good[k], bad[k]) for k in good)  # torch alone loads it
    with pytest.raises(CheckpointError, match=r"flipped.pt: damaged .* CRC"):
        universal.load(flipped)
