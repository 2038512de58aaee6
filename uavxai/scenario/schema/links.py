"""What the flight is seen and commanded through: `bridge` (the MAVLink link, ground
stations, signing), `log`, `environment` (wind, turbulence) and `surveillance` (ADS-B, the
onboard sensor, the tracker); the MAVLink link string's form."""

from __future__ import annotations

from typing import Annotated, Any, Literal

from pydantic import Field, field_validator, model_validator

from uavxai.errors import UserError
from uavxai.scenario.schema.base import (
    MAX_M,
    Probability,
    Section,
)


# --------------------------------------------------------------------------------------- bridge
class GroundStation(Section):
    """A ground station allowed to command: its MAVLink system id and its host's address."""

    system_id: Annotated[int, Field(ge=1, le=255)] = 255
    address: Annotated[str, Field(min_length=1, max_length=253)] = "127.0.0.1"

    @field_validator("address")
    @classmethod
    def _address(cls, v: str) -> str:
        import ipaddress

        try:
            return str(ipaddress.ip_address(v))
        except ValueError:
            raise ValueError(
                f"address must be an IP address (as the ground station's datagrams come "
                f"from, e.g. 127.0.0.1), got {v!r}"
            ) from None


class Bridge(Section):
    mavlink: Annotated[str, Field(max_length=500)] | None = None
    system_id: Annotated[int, Field(ge=1, le=255)] = 1
    signing_key_hex: str | None = None
    command_timeout_s: Annotated[float, Field(gt=0, le=600)] = 3.0  # failsafe: wings level
    # who may command without a signing key (none by default); with a key, signed commands
    ground_stations: Annotated[list[GroundStation], Field(max_length=16)] = []
    tlog: bool = True  # every frame in and out to RUN/link.tlog (uavxai run with a link)

    @model_validator(mode="before")
    @classmethod
    def _removed(cls, data: Any) -> Any:
        if isinstance(data, dict) and "override_s" in data:
            raise ValueError(
                "bridge.override_s was removed: an operator's command no longer switches "
                "avoidance off for a while, it sets where the ownship goes and avoidance "
                "stays on (see 'Operating from a ground station' in the README); delete the key"
            )
        return data

    @field_validator("signing_key_hex")
    @classmethod
    def _key(cls, v: str | None) -> str | None:
        if v is None:
            return v
        try:
            ok = len(v) == 64 and bytes.fromhex(v) is not None
        except ValueError:
            ok = False
        if not ok:
            raise ValueError("signing_key_hex must be exactly 64 hexadecimal digits (32 bytes)")
        return v.lower()

    @field_validator("mavlink")
    @classmethod
    def _url(cls, v: str | None) -> str | None:
        if v is not None:
            check_mavlink_url(v)
        return v


class Log(Section):
    rerun: bool = True


# ---------------------------------------------------------------------------------- environment
class Wind(Section):
    speed_mps: Annotated[float, Field(ge=0, le=100)] = 0.0
    from_deg: Annotated[float, Field(ge=0, le=360)] = 270.0  # blows FROM, clockwise from north


class Environment(Section):
    wind: Wind = Wind()
    turbulence: Literal["none", "light", "moderate", "severe"] = "none"


# --------------------------------------------------------------------------------- surveillance
class Sensor(Section):
    range_m: Annotated[float, Field(ge=0, le=MAX_M)] = 1000.0
    fov_deg: Annotated[float, Field(ge=0, le=360)] = 220.0
    sigma_m: Annotated[float, Field(ge=0, le=10_000)] = 10.0


class Surveillance(Section):
    model: Literal["adsb", "truth"] = "adsb"
    rate_hz: Annotated[float, Field(gt=0, le=100)] = 1.0
    nacp: Annotated[int, Field(ge=5, le=11)] = 10  # DO-260B categories with a bound
    nacv: Annotated[int, Field(ge=1, le=4)] = 2
    latency_s: Annotated[float, Field(ge=0, le=60)] = 0.5
    dropout: Annotated[float, Field(ge=0, lt=1)] = 0.05
    noncooperative: Probability = 0.0
    sensor: Sensor | None = Sensor()  # null: no onboard sensor
    preroll_s: Annotated[float, Field(ge=0, le=600)] = 10.0  # listening before t = 0
    # the filter of each track: ekf (one coordinated turn, its rate estimated) or imm
    # (straight, left and right turns mixed; uavxai.surveillance.imm)
    tracker: Literal["ekf", "imm"] = "ekf"


def check_mavlink_url(url: str) -> str:
    """Check the form of a pymavlink connection string (the bridge's rule, one place)."""
    from uavxai.link_url import check_link

    try:
        check_link(url)
    except UserError as exc:
        raise ValueError(str(exc)) from None
    return url
