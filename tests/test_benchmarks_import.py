"""Every benchmark script loads: its imports name what the package has (a benchmark that no
test runs went stale once, importing a `METHODS` the campaign package no longer had)."""

from __future__ import annotations

import importlib.util
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1] / "benchmarks"
KINDS = ("performance", "studies")  # speed against a baseline; what a method buys
BENCHMARKS = sorted(path for kind in KINDS for path in (ROOT / kind).glob("bench_*.py"))


def test_there_are_benchmarks() -> None:
    assert len(BENCHMARKS) >= 10


def test_every_benchmark_is_filed_by_kind() -> None:
    """A script left at the top or in another folder would escape this test and `make bench`."""
    stray = sorted(p.relative_to(ROOT) for p in ROOT.rglob("bench_*.py") if p not in BENCHMARKS)
    assert not stray, f"benchmarks outside {KINDS}: {stray}"


@pytest.mark.parametrize("path", BENCHMARKS, ids=lambda p: f"{p.parent.name}/{p.stem}")
def test_a_benchmark_script_loads(path: Path) -> None:
    spec = importlib.util.spec_from_file_location(f"_bench_{path.stem}", path)
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)  # module level only: main() runs under __main__
    assert callable(getattr(module, "main", None)), f"{path.name} has no main()"
