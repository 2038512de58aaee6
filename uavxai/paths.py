"""Where the data that travels with the package lives (aircraft XML, scenarios, checkpoints).

In the repository these are the top-level folders `aircraft/` and `scenarios/`; installed, they
are the sub-packages `uavxai.aircraft` and `uavxai.scenarios` (see pyproject.toml).
"""

from __future__ import annotations

from importlib.resources import files
from pathlib import Path


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
