"""The wheel carries the aircraft, scenarios and checkpoints, claims only `uavxai`, and every
module in it imports once installed."""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import zipfile
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def wheel(tmp_path_factory: pytest.TempPathFactory) -> zipfile.ZipFile:
    out = tmp_path_factory.mktemp("wheel")
    # Built from a copy without build/: setuptools reuses a stale build/lib, which would hide
    # a module missing from the package list.
    src = tmp_path_factory.mktemp("src") / "uavxai"
    skip = (".git", ".venv", "build", "dist", "runs", "*.egg-info", "__pycache__", ".*_cache")
    shutil.copytree(REPO, src, ignore=shutil.ignore_patterns(*skip))
    subprocess.run(
        [
            sys.executable,
            "-m",
            "pip",
            "wheel",
            "--no-deps",
            "--no-build-isolation",
            "-q",
            "-w",
            str(out),
            str(src),
        ],
        check=True,
        capture_output=True,
    )
    (whl,) = out.glob("uavxai-*.whl")
    return zipfile.ZipFile(whl)


def test_only_uavxai_top_level(wheel: zipfile.ZipFile) -> None:
    tops = {n.split("/")[0] for n in wheel.namelist() if not n.split("/")[0].endswith(".dist-info")}
    assert tops == {"uavxai"}, tops


def test_data_travels_with_the_wheel(wheel: zipfile.ZipFile) -> None:
    names = set(wheel.namelist())
    assert "uavxai/aircraft/uav_fw/uav_fw.xml" in names
    assert "uavxai/scenarios/demo.yaml" in names
    assert "uavxai/bridges/__init__.py" in names
    shipped = sorted(p.name for p in (REPO / "scenarios").glob("*.yaml"))
    assert all(f"uavxai/scenarios/{s}" in names for s in shipped)
    xml = sorted(str(p.relative_to(REPO / "aircraft")) for p in (REPO / "aircraft").rglob("*.xml"))
    assert all(f"uavxai/aircraft/{x}" in names for x in xml)
    for folder in ("uavxai/service/checkpoints", "uavxai/avoidance/checkpoints"):
        local = sorted(p.name for p in (REPO / folder).glob("*.pt"))
        assert all(f"{folder}/{p}" in names for p in local)


def test_entry_point_declared(wheel: zipfile.ZipFile) -> None:
    (ep,) = [n for n in wheel.namelist() if n.endswith("entry_points.txt")]
    assert "uavxai = uavxai.cli:main" in wheel.read(ep).decode()


def test_every_module_travels_with_the_wheel(wheel: zipfile.ZipFile) -> None:
    """Every module of the source tree is in the wheel (the package list was written by hand:
    uavxai.learning was missing, so `uavxai train --stage avoidance` failed after
    `pip install .`), and the encounter model's parameter file with its licence."""
    names = set(wheel.namelist())
    modules = sorted(str(p.relative_to(REPO)) for p in (REPO / "uavxai").rglob("*.py"))
    missing = [m for m in modules if m not in names]
    assert not missing, missing
    bridges = sorted(p.name for p in (REPO / "bridges").glob("*.py"))
    assert all(f"uavxai/bridges/{b}" in names for b in bridges)
    for data in ("uncor_1200only_fwse_v1p2.txt", "LICENSE", "README.md"):
        assert f"uavxai/encounters/data/{data}" in names


IMPORT_ALL = """
import importlib, json, sys
site = sys.argv[1]
sys.path.insert(0, site)
where = {}
for name in sys.argv[2:]:
    where[name] = importlib.import_module(name).__file__
print(json.dumps(where))
"""


@pytest.fixture(scope="module")
def site(wheel: zipfile.ZipFile, tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The wheel pip-installed into a folder of its own (no second venv)."""
    site = tmp_path_factory.mktemp("site")
    subprocess.run(
        [sys.executable, "-m", "pip", "install", "--no-deps", "--no-compile", "-q",
         "--target", str(site), wheel.filename],
        check=True,
        capture_output=True,
    )  # fmt: skip
    return site


def test_installed_wheel_imports_every_module(
    wheel: zipfile.ZipFile, site: Path, tmp_path: Path
) -> None:
    """pip installs the wheel (into a folder of its own: no second venv) and a fresh
    interpreter, outside the repository and without PYTHONPATH, imports every module the wheel
    holds from there. Only ``__main__`` is left out: importing it runs the command line."""
    modules = sorted(
        n.removesuffix(".py").removesuffix("/__init__").replace("/", ".")
        for n in wheel.namelist()
        if n.endswith(".py") and not n.endswith("__main__.py")
    )
    assert "uavxai.learning.train" in modules and "uavxai.bridges.link" in modules
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run(
        [sys.executable, "-c", IMPORT_ALL, str(site), *modules],
        cwd=tmp_path,
        env=env,
        capture_output=True,
        text=True,
        check=False,
    )
    assert proc.returncode == 0, proc.stderr[-3000:]
    where = json.loads(proc.stdout.splitlines()[-1])
    elsewhere = {m: f for m, f in where.items() if not Path(f).is_relative_to(site)}
    assert sorted(where) == modules and not elsewhere, elsewhere


def test_the_installed_wheel_trains_the_avoidance_stage(site: Path, tmp_path: Path) -> None:
    """Issue 29: after installing, `uavxai train --stage avoidance` runs from the installed
    copy (outside the repository, without PYTHONPATH) and writes its checkpoint."""
    scenario = tmp_path / "tiny.yaml"
    scenario.write_text("name: tiny\nintruders: {count: 2}\n")
    train = ("import sys; sys.path.insert(0, sys.argv[1]); import uavxai.cli as c; "
             "print('FROM', c.__file__); sys.exit(c.main(sys.argv[2:]))")  # fmt: skip
    env = {k: v for k, v in os.environ.items() if k != "PYTHONPATH"}
    proc = subprocess.run(
        [sys.executable, "-c", train, str(site), "train", str(scenario), "--stage",
         "avoidance", "--algo", "dqn", "--episodes", "1", "--out", str(tmp_path / "out")],
        cwd=tmp_path, env=env, capture_output=True, text=True, check=False,
    )  # fmt: skip
    assert proc.returncode == 0, proc.stderr[-3000:]
    where = next(ln for ln in proc.stdout.splitlines() if ln.startswith("FROM "))
    assert Path(where.removeprefix("FROM ")).is_relative_to(site)
    assert any((tmp_path / "out").rglob("*.pt")), sorted((tmp_path / "out").rglob("*"))
