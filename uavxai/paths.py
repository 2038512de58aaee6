"""Where the data that travels with the package lives (aircraft XML, scenarios, checkpoints).

In the repository these are the top-level folders `aircraft/` and `scenarios/`; installed, they
are the sub-packages `uavxai.aircraft` and `uavxai.scenarios` (see setup.py).
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import os
from importlib.resources import files
from pathlib import Path

from uavxai.errors import ScenarioError


def _dir(package: str) -> Path:
    return Path(str(files(package)))


def aircraft_dir() -> Path:
    """Folder holding one sub-folder per JSBSim aircraft (JSBSim's `aircraft path`)."""
    return _dir("uavxai.aircraft")


def scenarios_dir() -> Path:
    return _dir("uavxai.scenarios")


def service_checkpoints_dir() -> Path:
    return _dir("uavxai.service") / "checkpoints"


def avoidance_checkpoints_dir() -> Path:
    return _dir("uavxai.avoidance") / "checkpoints"


def shipped_scenarios() -> list[str]:
    """Names of the scenarios that ship with the package (``demo``, ``head_on``, ...)."""
    return sorted(p.stem for p in scenarios_dir().glob("*.yaml"))


def resolve_scenario(path: str | Path) -> Path:
    """The scenario file ``path`` names: a file, or the name of a shipped scenario (``demo``
    or ``demo.yaml``), so that a user of the installed wheel can run ``uavxai run demo``.
    A file of that name in the working folder wins over the shipped one."""
    text = str(path)
    if "\x00" in text:
        raise ScenarioError(f"{text!r}: a file name cannot contain a NUL byte.")
    p = Path(path)
    try:
        if p.is_file():
            return p
        exists = p.exists()
    except OSError as exc:  # e.g. a name too long for the file system
        raise ScenarioError(f"{text[:200]}: cannot read the scenario file ({exc}).") from None
    if exists:
        raise ScenarioError(f"{p}: not a file (expected a .yaml scenario file).")
    shipped = shipped_scenarios()
    stem = p.name.removesuffix(".yaml")
    if p.parent == Path(".") and stem in shipped:
        return scenarios_dir() / f"{stem}.yaml"
    raise ScenarioError(
        f"{text[:200]}: no such scenario file (expected a .yaml file, or the name of a shipped "
        f"scenario: {', '.join(shipped)})."
    )


def invocation(argv0: str | None = None) -> str:
    """How the user can start uavxai again from where they are: ``uavxai`` when that name on
    PATH is this program, else the path of the running script (``.venv/bin/uavxai`` after
    `make demo`, whose venv is not activated), or ``python -m uavxai`` for a module run."""
    import shlex
    import shutil
    import sys

    argv0 = sys.argv[0] if argv0 is None else argv0
    script = Path(argv0)
    if script.name in ("__main__.py", "-m", "-c", "") or not script.is_file():
        return f"{shlex.quote(sys.executable)} -m uavxai"
    on_path = shutil.which("uavxai")
    if on_path is not None and Path(on_path).resolve() == script.resolve():
        return "uavxai"
    shown = argv0 if os.sep in argv0 else str(script.resolve())
    return shlex.quote(shown)


def scenario_catalogue() -> list[tuple[str, str, Path]]:
    """Every shipped scenario: (name, one line on what it flies, its file). The line is the
    first sentence of the file's leading comment (the scenario schema has no description
    key), cut to 100 characters."""
    rows = []
    for name in shipped_scenarios():
        path = scenarios_dir() / f"{name}.yaml"
        comment = []
        with path.open(encoding="utf-8") as f:
            for line in f:
                if not line.startswith("#"):
                    break
                comment.append(line.lstrip("#").strip())
        text = " ".join(comment)
        first = text.split(". ")[0].rstrip(".") + "." if text else "(no description)"
        rows.append((name, first if len(first) <= 100 else first[:97] + "...", path))
    return rows


def source_digest(root: Path | None = None) -> str:
    """A digest of the code and data uavxai flies with: every file of the package ``root``
    (None: this installed uavxai, and its aircraft, which a source checkout keeps beside it)
    but compiled bytecode, by relative path and content. Two processes with the same digest
    fly the same episodes; a version number does not say that between two commits (a
    resumed campaign, a Ray cluster)."""
    return _digest(Path(root)) if root is not None else _installed_digest()


@functools.cache  # read once: the files of a running process's package do not change
def _installed_digest() -> str:
    spec = importlib.util.find_spec("uavxai.bridges")  # found, not imported (a higher layer)
    bridges = Path(next(iter(spec.submodule_search_locations)))
    return installation_digest(Path(__file__).parent, bridges, aircraft_dir())


def installation_digest(package: Path, bridges: Path, aircraft: Path) -> str:
    """:func:`source_digest` of an installation: its ``package`` folder, and the MAVLink
    bridge (``uavxai.bridges``) and ``aircraft`` where they live outside it. A wheel keeps
    them inside the package; a source checkout beside it, where an editable install maps them
    in: their code and data fly every episode too (found when campaigns flown from other
    checkouts of this repository imported this checkout's bridge, unseen by the digest)."""
    package, bridges = package.resolve(), bridges.resolve()
    beside = "" if bridges.is_relative_to(package) else _digest(bridges)[:8]
    return _digest(package) + beside + _digest(aircraft.resolve())[:8]


def _digest(root: Path) -> str:
    h = hashlib.sha256()
    for path in sorted(p for p in root.rglob("*") if p.is_file()):
        if "__pycache__" in path.parts or path.suffix == ".pyc":
            continue
        h.update(path.relative_to(root).as_posix().encode() + b"\0")
        h.update(hashlib.sha256(path.read_bytes()).digest())
    return h.hexdigest()[:16]
