"""Hostile service-point checkpoints (issue 30): declared sizes bounded and compared with the
stored tensors before a network is allocated, non-finite weights refused, each with a message
naming the file, the field and what is allowed; exit 2 through the CLI."""

from __future__ import annotations

import re
import subprocess
import sys
from pathlib import Path

import pytest
import torch

from uavxai.cli import main
from uavxai.errors import CheckpointError
from uavxai.learning import branching, checkpoint
from uavxai.paths import service_checkpoints_dir
from uavxai.service import d3qn, universal

SHIPPED = service_checkpoints_dir() / "universal_d3qn_l6.pt"


@pytest.fixture
def good_d3qn(tmp_path: Path) -> Path:
    torch.manual_seed(0)
    cfg = branching.D3QNConfig(hidden=8, layers=2)
    net = d3qn.BranchingQNetwork(10, 2, 3, cfg.hidden, cfg.layers, cfg.dueling)
    path = tmp_path / "good.pt"
    branching.save_checkpoint(path, net, "d3qn", cfg, meta={"note": "ok"})
    return path


def tampered(path: Path, tmp_path: Path, change, name: str = "bad.pt") -> Path:
    data = torch.load(path, map_location="cpu", weights_only=True)
    change(data)
    out = tmp_path / name
    torch.save(data, out)
    return out


def test_good_checkpoints_load(good_d3qn: Path) -> None:
    net, info = d3qn.load_checkpoint(good_d3qn)
    assert info["k"] == 2 and info["power_levels"] == 3 and info["meta"] == {"note": "ok"}
    assert net.trunk[0].in_features == 10
    net, info = universal.load(SHIPPED)
    assert info["power_levels"] == 6 and net.hidden == 64


@pytest.mark.parametrize(
    ("field", "value", "allowed"),
    [
        ("hidden", 16_000, f"from 1 to {checkpoint.MAX_HIDDEN_WIDTH}"),
        ("obs_dim", 16_000, f"from 1 to {checkpoint.MAX_OBS_DIM}"),
        ("k", 10**9, f"from 1 to {checkpoint.MAX_USERS}"),
        ("power_levels", 0, f"from 1 to {checkpoint.MAX_POWER_LEVELS}"),
        ("layers", 10**6, f"from 1 to {checkpoint.MAX_LAYERS}"),
        ("hidden", 8.0, "an integer"),
        ("hidden", True, "an integer"),
        ("dueling", "yes", "true or false"),
    ],
)
def test_d3qn_declared_sizes_are_bounded(good_d3qn, tmp_path, field, value, allowed) -> None:
    """The issue's bomb: 1.5 kB declaring 16,000 x 16,000 layers; each field alike."""
    path = tampered(good_d3qn, tmp_path, lambda d: d.update({field: value}))
    with pytest.raises(CheckpointError) as err:
        d3qn.load_checkpoint(path)
    msg = str(err.value)
    assert str(path) in msg and f"{field} = " in msg and allowed in msg, msg


def test_universal_hidden_60000_is_refused(tmp_path: Path) -> None:
    path = tampered(SHIPPED, tmp_path, lambda d: d.update(hidden=60_000))
    assert path.stat().st_size < 200_000
    with pytest.raises(CheckpointError, match=r"hidden = 60000; allowed: an integer from 1 to"):
        universal.load(path)


@pytest.mark.parametrize("loader", ["d3qn", "universal"])
def test_sizes_within_bounds_but_not_the_stored_tensors_allocate_nothing(
    good_d3qn: Path, tmp_path: Path, loader: str
) -> None:
    """Declared sizes within the bounds, yet far larger than the tensors stored: refused on
    shapes compared on the meta device. The child's peak resident size shows that the 512 MB
    network the declaration describes was never built."""
    if loader == "d3qn":
        path = tampered(good_d3qn, tmp_path, lambda d: d.update(hidden=4096, layers=8))
        call = "from uavxai.service.d3qn import load_checkpoint as load"
    else:
        path = tampered(SHIPPED, tmp_path, lambda d: d.update(hidden=4096))
        call = "from uavxai.service.universal import load"
    code = (
        f"import re; {call}\n"
        "from uavxai.errors import CheckpointError\n"
        f"try:\n    load({str(path)!r}); print('loaded')\n"
        "except CheckpointError as e:\n    print('refused', str(e).replace(chr(10), ' '))\n"
        "print(re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1))\n"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    verdict, peak_kb = proc.stdout.strip().rsplit("\n", 1)
    assert verdict.startswith("refused") and "do not have the declared sizes" in verdict, verdict
    # built, the declared network alone would add ~400 MB (universal) or 512 MB (d3qn) to
    # the ~300 MB that importing torch takes
    assert int(peak_kb) < 650_000, f"peak {int(peak_kb) / 1024:.0f} MB"


@pytest.mark.parametrize("value", [float("nan"), float("inf")])
def test_non_finite_service_weights_are_refused(good_d3qn, tmp_path, value) -> None:
    def poison(d: dict) -> None:
        for v in d["state_dict"].values():
            v.fill_(value)

    for load, src in ((d3qn.load_checkpoint, good_d3qn), (universal.load, SHIPPED)):
        path = tampered(src, tmp_path, poison)
        with pytest.raises(CheckpointError, match="non-finite values.*allowed: finite") as err:
            load(path)
        assert str(path) in str(err.value)


def test_an_all_nan_service_checkpoint_exits_2_through_the_cli(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """Before: accepted, and the service point planned with objective 0."""

    def poison(d: dict) -> None:
        for v in d["state_dict"].values():
            v.fill_(float("nan"))

    path = tampered(SHIPPED, tmp_path, poison, "nan.pt")
    scenario = tmp_path / "s.yaml"
    scenario.write_text(f"name: nan-service\nservice: {{planner: d3qn, checkpoint: {path}}}\n")
    out = tmp_path / "out"
    assert main(["service", str(scenario), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and "internal error" not in err
    assert str(path) in err and re.search("non-finite values", err), err
    assert not out.exists()
