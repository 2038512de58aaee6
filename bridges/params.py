"""The read-only parameter table ground stations download before they call a vehicle connected.

Every value is sent as MAV_PARAM_TYPE_REAL32; the index of a name is its position in the table
and never changes during a session, as PARAM_VALUE's param_index requires.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

from pymavlink.dialects.v20 import common as mavlink

PARAM_ID_CHARS = 16


class ParamTable:
    def __init__(self, values: Mapping[str, float]) -> None:
        for name, value in values.items():
            if not name or len(name) > PARAM_ID_CHARS or not name.isascii():
                raise ValueError(f"parameter name {name!r}: 1 to 16 ASCII characters")
            if not math.isfinite(float(value)):
                raise ValueError(f"parameter {name} = {value} is not a finite number")
        self._names = list(values)
        self._values = {name: float(v) for name, v in values.items()}

    def __len__(self) -> int:
        return len(self._names)

    def index_of(self, name: str) -> int | None:
        return self._names.index(name) if name in self._values else None

    def value_message(self, index: int) -> mavlink.MAVLink_param_value_message:
        """PARAM_VALUE of the parameter at `index` (0 <= index < len)."""
        name = self._names[index]
        return mavlink.MAVLink_param_value_message(
            name.encode("ascii"),
            self._values[name],
            mavlink.MAV_PARAM_TYPE_REAL32,
            len(self._names),
            index,
        )

    def find(self, param_id: str, param_index: int) -> int | None:
        """Index a PARAM_REQUEST_READ asks for: by index if >= 0, else by name (-1 convention)."""
        if param_index >= 0:
            return param_index if param_index < len(self._names) else None
        return self.index_of(param_id)
