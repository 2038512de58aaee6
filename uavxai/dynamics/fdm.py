"""JSBSim executives for the aircraft under ``aircraft/``: silent, logging to Python.

JSBSim prints to the console unless ``JSBSIM_DEBUG=0`` is set before the first
``FGFDMExec`` is created, and even then sends warnings (trim failures, unknown properties)
to its logger. Both are taken care of here, so nothing reaches stdout; JSBSim's messages go
to the ``uavxai.jsbsim`` Python logger instead.
"""

from __future__ import annotations

import logging
import os
import threading

os.environ.setdefault("JSBSIM_DEBUG", "0")  # before the first FGFDMExec; 1 for debugging

import jsbsim  # noqa: E402

from uavxai.errors import UserError  # noqa: E402
from uavxai.paths import aircraft_dir  # noqa: E402

log = logging.getLogger("uavxai.jsbsim")

_LEVELS = {
    jsbsim.LogLevel.BULK: logging.DEBUG,
    jsbsim.LogLevel.DEBUG: logging.DEBUG,
    jsbsim.LogLevel.INFO: logging.INFO,
    jsbsim.LogLevel.STDOUT: logging.INFO,
    jsbsim.LogLevel.WARN: logging.WARNING,
    jsbsim.LogLevel.ERROR: logging.ERROR,
    jsbsim.LogLevel.FATAL: logging.CRITICAL,
}


class _PythonLogger(jsbsim.FGLogger):
    """Collects the fragments of one JSBSim log record and emits it as one Python record."""

    def __init__(self) -> None:
        super().__init__()
        self._level = logging.INFO
        self._where = ""
        self._parts: list[str] = []

    def set_level(self, level: jsbsim.LogLevel) -> None:
        self._level = _LEVELS.get(level, logging.INFO)
        self._where = ""
        self._parts = []

    def file_location(self, filename: str, line: int) -> None:
        self._where = f"{filename}:{line}: "

    def message(self, message: str) -> None:
        self._parts.append(message)

    def format(self, format: jsbsim.LogFormat) -> None:
        pass  # colours and emphasis mean nothing in a log file

    def flush(self) -> None:
        text = "".join(self._parts).strip()
        self._parts = []
        if text:
            log.log(self._level, "%s%s", self._where, text)


_thread = threading.local()


def _route_jsbsim_logging() -> None:
    # JSBSim keeps its logger per thread.
    if not getattr(_thread, "logger", None):
        _thread.logger = _PythonLogger()
        jsbsim.set_logger(_thread.logger)


def known_aircraft() -> list[str]:
    root = aircraft_dir()
    return sorted(p.name for p in root.iterdir() if (p / f"{p.name}.xml").is_file())


def load_fdm(aircraft: str, dt: float) -> jsbsim.FGFDMExec:
    """A JSBSim executive with ``aircraft/<aircraft>/<aircraft>.xml`` loaded, stepping at ``dt``.

    Engines and systems are found in the aircraft's own ``Engines/`` and ``Systems/`` folders.
    """
    if aircraft not in known_aircraft():
        raise UserError(
            f"aircraft '{aircraft}' is not a folder under {aircraft_dir()}; "
            f"known: {', '.join(known_aircraft())}"
        )
    _route_jsbsim_logging()
    fdm = jsbsim.FGFDMExec(None)
    fdm.set_debug_level(0)
    fdm.set_aircraft_path(str(aircraft_dir()))
    if not fdm.load_model(aircraft):
        raise UserError(
            f"JSBSim could not load aircraft '{aircraft}' from {aircraft_dir() / aircraft}; "
            "see the 'uavxai.jsbsim' log for its messages"
        )
    fdm.set_dt(dt)
    return fdm
