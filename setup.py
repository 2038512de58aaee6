"""The wheel's packages, found rather than listed (issue 29: a hand-written list in
pyproject.toml left `uavxai.learning` out, so `uavxai train --stage avoidance` failed after
`pip install .`). Everything else about the build is in pyproject.toml.

`bridges/`, `aircraft/` and `scenarios/` sit at the top of the repository but install inside
the uavxai namespace, so that no generic top-level name (`bridges`, `aircraft`) is claimed;
pyproject.toml's `[tool.setuptools]` cannot combine `find` with such a mapping, hence this file.
"""

from setuptools import find_packages, setup

INSIDE = {
    "uavxai.bridges": "bridges",
    "uavxai.aircraft": "aircraft",
    "uavxai.scenarios": "scenarios",
}


def packages() -> list[str]:
    found = find_packages(include=["uavxai", "uavxai.*"])
    for name, folder in INSIDE.items():
        found += [name, *(f"{name}.{sub}" for sub in find_packages(folder))]
    return found


setup(packages=packages(), package_dir=INSIDE)
