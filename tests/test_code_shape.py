"""House rules the code keeps: short functions (the MCTS inner loop excepted), one vocabulary."""

from __future__ import annotations

import ast
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
