"""Scenario schema: defaults, ranges, and broken files that must exit 2 with a clear message."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from uavxai.cli import main
from uavxai.errors import ScenarioError
from uavxai.paths import scenarios_dir
from uavxai.scenario import default_scenario, load_scenario

REPO = Path(__file__).resolve().parents[1]


def test_defaults_match_spec() -> None:
    sc = default_scenario()
    assert sc.seed == 0
    assert sc.world.x == (0, 2000) and sc.world.h == (50, 300)
    assert sc.comms.users.k == 10 and sc.comms.power_levels == 6 and sc.comms.p_max_w == 1.0
    assert sc.comms.environment == "urban" and sc.comms.access == "shared"
    assert sc.service.planner == "d3qn" and sc.service.steps == 100
    assert sc.intruders.count == 20 and sc.intruders.speed_mps == (15, 30)
    assert sc.avoidance.planner == "mcts" and sc.avoidance.d_min_m == 50
    assert sc.avoidance.mcts.simulations == 200 and sc.avoidance.mcts.depth == 4
    assert sc.bridge.system_id == 1 and sc.log.rerun is True


def test_every_shipped_scenario_validates() -> None:
    files = sorted(scenarios_dir().glob("*.yaml"))
    assert any(f.name == "demo.yaml" for f in files)
    for f in files:
        assert load_scenario(f).name


def test_demo_uses_the_defaults() -> None:
    demo = load_scenario(scenarios_dir() / "demo.yaml")
    assert demo == default_scenario("demo")


# (file content, words the message must contain)
BROKEN: list[tuple[str, tuple[str, ...]]] = [
    ("name: x\nworld: {x: [0, 100], hh: 3}\n", ("world.hh", "Did you mean 'h'")),
    ("name: x\ncoms: {}\n", ("coms", "Did you mean 'comms'")),
    ("name: x\ncomms: {power_levels: 1}\n", ("comms.power_levels", "greater than or equal to 2")),
    ("name: x\ncomms: {p_max_w: 0}\n", ("comms.p_max_w", "greater than 0")),
    ("name: x\ncomms: {p_max_w: 1 W}\n", ("comms.p_max_w", "number")),
    ("name: x\ncomms: {environment: rural}\n", ("comms.environment", "urban")),
    ("name: x\ncomms: {access: tdma}\n", ("comms.access", "ofdma")),
    ("name: x\nworld: {h: [300, 50]}\n", ("world.h", "min < max")),
    ("name: x\nworld: {h: [-10, 50]}\n", ("world.h", "above the ground")),
    ("name: x\nworld: {x: [0]}\n", ("world.x",)),
    ("seed: 3\n", ("name", "required")),
    ("name: x\nseed: -1\n", ("seed", "greater than or equal to 0")),
    ("name: x\navoidance: {planner: astar}\n", ("avoidance.planner", "mcts")),
    ("name: x\navoidance: {mcts: {depth: 0}}\n", ("avoidance.mcts.depth",)),
    ("name: x\navoidance: {bank_step_deg: 40}\n", ("bank_step_deg", "bank_limit_deg")),
    ("name: x\nownship: {start: {x: 5000}}\n", ("ownship.start", "outside the world")),
    ("name: x\nownship: {aircraft: cessna}\n", ("aircraft 'cessna'", "known")),
    ("name: x\nbridge: {signing_key_hex: abc}\n", ("signing_key_hex", "64 hexadecimal")),
    ("name: x\nbridge: {mavlink: 'http://x'}\n", ("bridge.mavlink", "udpout:HOST:PORT")),
    ("name: x\ncomms: {users: {count: 3, positions: [[1, 2]]}}\n", ("comms.users", "count is 3")),
    ("name: x\ncomms: {users: {region: {x: [0, 5000]}}}\n", ("region", "inside the world")),
    ("name: x\nintruders: {list: [{x: 1, y: 2}]}\n", ("intruders.list.0.h", "required")),
    ("name: x\nworld: [1, 2\n", ("not valid YAML", "line")),
    ("- just\n- a list\n", ("YAML mapping",)),
    ("", ("YAML mapping", "empty")),
    ("name: x\nworld: {x: [0, .inf]}\n", ("world.x",)),
]


@pytest.mark.parametrize(("text", "words"), BROKEN, ids=[str(i) for i in range(len(BROKEN))])
def test_broken_scenario_message(tmp_path: Path, text: str, words: tuple[str, ...]) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert str(path) in msg
    for w in words:
        assert w in msg, f"{w!r} not in message:\n{msg}"


@pytest.mark.parametrize(("text", "words"), BROKEN[:6] + BROKEN[-4:])
def test_validate_exits_2_without_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, words: tuple[str, ...]
) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(path) in err


def test_missing_and_binary_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert "no such scenario file" in capsys.readouterr().err
    binary = tmp_path / "bin.yaml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    assert main(["validate", str(binary)]) == 2
    assert "cannot read" in capsys.readouterr().err or "YAML" in capsys.readouterr().err


def test_validate_ok(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(REPO / "scenarios" / "demo.yaml")]) == 0
    assert "valid scenario 'demo'" in capsys.readouterr().out


def test_bad_flags_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    demo = str(REPO / "scenarios" / "demo.yaml")
    for argv in (
        ["run", demo, "--seed", "abc"],
        ["run", demo, "--mavlink", "serial0"],
        ["run", demo, "--realtime", "-1"],
        ["evaluate", demo, "--methods", "mcts,astar", "--intruders", "5"],
        ["evaluate", demo, "--methods", "mcts", "--intruders", "five"],
        ["train", demo, "--stage", "avoidance", "--algo", "d3qn"],
        ["frobnicate"],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "error" in err and "Traceback" not in err


def test_existing_output_is_not_overwritten(tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    demo = str(REPO / "scenarios" / "demo.yaml")
    assert main(["service", demo, "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "precious"


def test_console_script_runs() -> None:
    """The installed `uavxai` entry point exists and exits 2 on a bad file."""
    proc = subprocess.run(
        [sys.executable, "-m", "uavxai", "validate", "/nonexistent.yaml"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr
