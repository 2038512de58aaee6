"""House rules the code keeps: short functions (the MCTS inner loop excepted), one vocabulary."""

from __future__ import annotations

import ast
import dataclasses
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
MAX_LINES = 80
# The search's inner loop stays one readable piece: splitting it costs a call per simulation.
EXEMPT = {("uavxai/avoidance/mcts.py", "search")}


def _long_functions() -> list[str]:
    found = []
    for folder in ("uavxai", "bridges"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            rel = path.relative_to(ROOT).as_posix()
            for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
                if isinstance(node, ast.FunctionDef | ast.AsyncFunctionDef):
                    n = node.end_lineno - node.lineno + 1
                    if n > MAX_LINES and (rel, node.name) not in EXEMPT:
                        found.append(f"{rel}:{node.lineno} {node.name} ({n} lines)")
    return found


def test_no_function_is_longer_than_80_lines_but_the_search_loop() -> None:
    assert _long_functions() == []


def test_action_and_planner_names_are_written_once() -> None:
    """The action table and the planner names live in uavxai/vocabulary.py; no other module
    spells out the 9 actions' names or the list of planners."""
    offenders = []
    for path in sorted((ROOT / "uavxai").rglob("*.py")):
        if path.name == "vocabulary.py":
            continue
        text = path.read_text(encoding="utf-8")
        if '"bank left, speed up"' in text or '("mcts", "mcts_fast"' in text:
            offenders.append(path.relative_to(ROOT).as_posix())
    assert offenders == []


def _contract_layers() -> list[str]:
    import tomllib

    config = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))
    contract = next(c for c in config["tool"]["importlinter"]["contracts"]
                    if c["type"] == "layers")  # fmt: skip
    names = []
    for layer in contract["layers"]:
        names += [n.strip() for n in layer.replace("|", ":").split(":")]
    return names


def test_every_module_of_the_package_has_a_layer() -> None:
    """The import-linter contract (make test runs it) can only hold the modules it names: a new
    module outside every layer would import what it likes unseen."""
    layered = set(_contract_layers())
    modules = {f"uavxai.{p.stem}" for p in (ROOT / "uavxai").glob("*.py")
               if p.stem not in ("__init__", "__main__")}  # fmt: skip
    packages = {f"uavxai.{p.parent.name}" for p in (ROOT / "uavxai").glob("*/__init__.py")}
    # A package split over two layers (uavxai.learning: the trainers above the engine, the
    # checkpoint reader below the planners) is covered when every module of it is named.
    for package in sorted(packages - layered):
        folder = ROOT / package.replace(".", "/")
        inner = {f"{package}.{p.stem}" for p in folder.glob("*.py") if p.stem != "__init__"}
        if inner and inner <= layered:
            packages.discard(package)
    assert sorted((modules | packages) - layered) == []


# What the MAVLink side may use of the package: it is installed as uavxai.bridges from the
# repository's top (setup.py), where the import linter does not look, so this test does. It sits
# above the dynamics (geodesy, state) and below what flies it (sim, surveillance).
BRIDGE_MAY_IMPORT = ("uavxai.errors", "uavxai.geometry", "uavxai.units", "uavxai.vocabulary",
                     "uavxai.link_url", "uavxai.dynamics.geodesy", "uavxai.dynamics.state",
                     "uavxai.bridges")  # fmt: skip


def test_the_bridge_imports_only_the_layers_below_it() -> None:
    wrong = []
    for path in sorted((ROOT / "bridges").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            names = []
            if isinstance(node, ast.ImportFrom) and node.module and node.level == 0:
                names = [node.module]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            for name in names:
                if name.startswith("uavxai") and not name.startswith(BRIDGE_MAY_IMPORT):
                    wrong.append(f"{path.name}: {name}")
    assert wrong == []


def test_planner_settings_are_declared_once_in_the_schema() -> None:
    """PlannerConfig's fields for what the scenario declares are the schema's, generated from
    it with its defaults (uavxai.avoidance.settings); PlannerConfig's own body declares none of
    them again (a field declared there would silently override the schema's default)."""
    from uavxai.avoidance.settings import SCHEMA_PATHS, SchemaSettings, schema_settings
    from uavxai.avoidance.types import PlannerConfig
    from uavxai.scenario import Avoidance, World

    assert set(PlannerConfig.__annotations__).isdisjoint(SCHEMA_PATHS)
    assert [f.name for f in dataclasses.fields(SchemaSettings)] == list(SCHEMA_PATHS)
    mapped = schema_settings(Avoidance(), World())
    assert len(mapped) >= 20
    default = PlannerConfig()
    assert {k: getattr(default, k) for k in mapped} == mapped
    changed = schema_settings(Avoidance(d_min_m=80.0, mcts={"depth": 3}), World(x=(0, 900)))
    assert (changed["d_min_m"], changed["depth"], changed["x_bounds"]) == (80.0, 3, (0.0, 900.0))
