"""A scenario file read as untrusted input: its size bounded before a byte is read, its YAML
parsed within bounded depth and node count (aliases expanded), duplicate keys refused,
relative checkpoint paths made absolute, then validated against the schema; every problem a
:class:`ScenarioError` naming the file.
"""

from __future__ import annotations

import os
import re
import stat
from pathlib import Path
from typing import Any

import yaml
from pydantic import ValidationError

from uavxai.errors import ScenarioError
from uavxai.paths import resolve_scenario
from uavxai.scenario.messages import REFERENCE, invalid_scenario, short_value
from uavxai.scenario.schema import Scenario


# ------------------------------------------------------------------------------ validation
def parse_scenario(data: Any, source: str = "<scenario>") -> Scenario:
    """Validate already-parsed YAML data."""
    if not isinstance(data, dict):
        kind = type(data).__name__ if data is not None else "an empty document"
        raise ScenarioError(
            f"{source}: a scenario must be a YAML mapping of keys (name, world, comms, ...), "
            f"got {kind}. See {REFERENCE}."
        )
    try:
        return Scenario.model_validate(data)
    except ValidationError as exc:
        raise ScenarioError(invalid_scenario(source, exc.errors(), Scenario)) from None
    except RecursionError:  # data built in Python, not by load_scenario's bounded loader
        raise ScenarioError(f"{source}: the scenario is nested too deeply.") from None


# ------------------------------------------------------------------------------ bounded YAML
MAX_FILE_BYTES = 256_000  # a scenario with 500 listed intruders is about 40 kB
MAX_DEPTH = 32  # the schema nests 4 deep; lists of lists add 2
MAX_NODES = 20_000  # with aliases expanded; 500 listed intruders are about 6,600


class _BoundedLoader(yaml.SafeLoader):
    """PyYAML's safe loader, bounded: nesting depth, node count with every alias expanded,
    integer length; duplicate keys are an error (PyYAML keeps the last one silently)."""

    def __init__(self, stream: str) -> None:
        super().__init__(stream)
        self._depth = 0
        self._nodes = 0

    def compose_node(self, parent: Any, index: Any) -> Any:  # noqa: D102
        self._depth += 1
        self._nodes += 1
        if self._depth > MAX_DEPTH:
            raise yaml.constructor.ConstructorError(
                None, None, f"nested deeper than {MAX_DEPTH} levels", self.peek_event().start_mark
            )
        if self._nodes > MAX_NODES:
            raise yaml.constructor.ConstructorError(
                None, None, f"more than {MAX_NODES} values", self.peek_event().start_mark
            )
        try:
            return super().compose_node(parent, index)
        finally:
            self._depth -= 1

    def construct_mapping(self, node: Any, deep: bool = False) -> Any:  # noqa: D102
        if isinstance(node, yaml.MappingNode):
            seen: set[Any] = set()
            for key_node, _ in node.value:
                if key_node.tag == "tag:yaml.org,2002:merge" or not isinstance(
                    key_node, yaml.ScalarNode
                ):
                    continue
                key = key_node.value
                if key in seen:
                    raise yaml.constructor.ConstructorError(
                        "while reading a mapping",
                        node.start_mark,
                        f"duplicate key '{short_value(key)[1:-1]}' (YAML keeps only one: give it "
                        "once)",
                        key_node.start_mark,
                    )
                seen.add(key)
        return super().construct_mapping(node, deep=deep)

    def construct_yaml_int(self, node: Any) -> int:  # noqa: D102
        if len(node.value) > 40:
            raise yaml.constructor.ConstructorError(
                None, None, f"an integer of {len(node.value)} characters is too large",
                node.start_mark,
            )
        return super().construct_yaml_int(node)


_BoundedLoader.add_constructor("tag:yaml.org,2002:int", _BoundedLoader.construct_yaml_int)


# YAML 1.2 reads 1e3 and 2.5E-4 as numbers; PyYAML (YAML 1.1) wants a dot and a signed
# exponent (1.0e+3) and otherwise gives text, which the strict schema refuses. Read them as
# numbers here, as a user means them; quoted ('1e3') they stay text.
_BoundedLoader.add_implicit_resolver(
    "tag:yaml.org,2002:float",
    re.compile(r"^[-+]?(?:[0-9][0-9_]*(?:\.[0-9_]*)?|\.[0-9_]+)[eE][-+]?[0-9]+$"),
    list("-+0123456789."),
)


class _CycleError(Exception):
    def __init__(self, mark: Any) -> None:
        self.mark = mark


def _expanded_size(root: Any) -> int:
    """Number of nodes of the composed document with every alias expanded, stopping as soon as
    it passes MAX_NODES (the "billion laughs" file: 400 bytes, 10^9 nodes once expanded)."""
    memo: dict[int, int] = {}

    def size(node: Any) -> int:
        key = id(node)
        if key in memo:
            if memo[key] < 0:
                raise _CycleError(node.start_mark)
            return memo[key]
        memo[key] = -1  # being counted: meeting it again inside itself is a cycle
        total = 1
        if isinstance(node, yaml.SequenceNode):
            for child in node.value:
                total += size(child)
                if total > MAX_NODES:
                    break
        elif isinstance(node, yaml.MappingNode):
            for k, v in node.value:
                total += size(k) + size(v)
                if total > MAX_NODES:
                    break
        memo[key] = total
        return total

    return size(root)


def safe_yaml(text: str, source: str) -> Any:
    """Parse untrusted YAML text within bounded time and memory; :class:`ScenarioError`
    naming ``source`` and the line on any problem."""
    if len(text) > MAX_FILE_BYTES:
        raise ScenarioError(
            f"{source}: {len(text)} characters is too large for a scenario file (at most "
            f"{MAX_FILE_BYTES}); see {REFERENCE}."
        )
    loader = None
    try:
        loader = _BoundedLoader(text)  # its reader checks the characters already
        root = loader.get_single_node()
        if root is None:
            return None
        if _expanded_size(root) > MAX_NODES:
            raise ScenarioError(
                f"{source}: with its aliases (*name) expanded the file holds more than "
                f"{MAX_NODES} values; a scenario needs far fewer. Write the values out or "
                "use fewer nested aliases."
            )
        return loader.construct_document(root)
    except _CycleError as cycle:
        raise ScenarioError(
            f"{source}: not valid YAML at line {cycle.mark.line + 1}: an alias (*name) refers to "
            "the mapping or list that contains it, which never ends."
        ) from None
    except yaml.YAMLError as exc:
        mark = getattr(exc, "problem_mark", None)
        where = f" at line {mark.line + 1}, column {mark.column + 1}" if mark else ""
        problem = getattr(exc, "problem", None) or str(exc).splitlines()[0]
        raise ScenarioError(f"{source}: not valid YAML{where}: {problem}.") from None
    except (ValueError, OverflowError, RecursionError) as exc:  # e.g. int('1' * 5000)
        raise ScenarioError(
            f"{source}: not a readable scenario ({type(exc).__name__}: {short_value(str(exc))})."
        ) from None
    finally:
        if loader is not None:
            loader.dispose()


def _absolute_paths(data: Any, folder: Path) -> Any:
    """Relative checkpoint paths resolve against the scenario file's folder, here, once, so
    that every process (local workers, Ray workers) sees the same absolute path."""
    if not isinstance(data, dict):
        return data
    for section in ("service", "avoidance"):
        sub = data.get(section)
        if isinstance(sub, dict):
            ckpt = sub.get("checkpoint")
            if isinstance(ckpt, str) and ckpt and "\x00" not in ckpt:
                try:
                    path = Path(ckpt).expanduser()
                except RuntimeError:  # ~user that does not exist: reported as no such file
                    path = Path(ckpt)
                if not path.is_absolute():
                    path = folder / path
                data = {**data, section: {**sub, "checkpoint": str(path)}}
    return data


# UTF-8 takes at most 4 bytes a character: a file of more bytes has too many characters.
MAX_READ_BYTES = 4 * MAX_FILE_BYTES


def _too_large(p: Path, size: str) -> ScenarioError:
    return ScenarioError(
        f"{p}: {size} is too large for a scenario file (at most {MAX_FILE_BYTES} characters); "
        f"see {REFERENCE}."
    )


def read_scenario_text(p: Path) -> str:
    """A scenario file's text, never reading more than :data:`MAX_READ_BYTES` + 1 bytes: a
    file is refused by its size (stat) before a byte is read, and the read itself is bounded
    (a file that grows meanwhile)."""
    try:
        with p.open("rb") as f:
            st = os.fstat(f.fileno())
            if stat.S_ISREG(st.st_mode) and st.st_size > MAX_READ_BYTES:
                raise _too_large(p, f"{st.st_size} bytes")
            raw = f.read(MAX_READ_BYTES + 1)
    except OSError as exc:
        raise ScenarioError(f"{p}: cannot read the scenario file ({exc}).") from None
    if len(raw) > MAX_READ_BYTES:
        raise _too_large(p, f"more than {MAX_READ_BYTES} bytes")
    try:
        return raw.decode("utf-8")
    except UnicodeDecodeError as exc:
        raise ScenarioError(f"{p}: cannot read the scenario file ({exc}).") from None


def load_scenario(path: str | Path) -> Scenario:
    """Read and validate a scenario YAML file; raises :class:`ScenarioError` on any problem.

    ``path`` may also be the name of a shipped scenario (``demo``, ``head_on``, ...)."""
    p = resolve_scenario(path)
    text = read_scenario_text(p)
    data = safe_yaml(text, str(p))
    return parse_scenario(_absolute_paths(data, p.resolve().parent), str(p))


def default_scenario(name: str = "demo", **overrides: Any) -> Scenario:
    """A scenario with every default, for tests and library users."""
    return parse_scenario({"name": name, **overrides})
