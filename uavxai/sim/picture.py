"""What the planner believes of the traffic: surveillance, the ADS-B link, the tracker.

Every sample the surveillance model (``surveillance:``) produces the reports due then: ADS-B
from cooperative intruders (rate, NACp/NACv noise, latency, dropouts) and the onboard
sensor's detections of the others. The ADS-B reports are packed as MAVLink ADSB_VEHICLE
frames and decoded back, as a companion computer receiving them would; in ``uavxai run``
the same frames also go out on the bridge's link, so a ground station shows the traffic the
planner sees and a real receiver could replace the simulated one. Both command paths pack and
decode alike, so a seed gives the same beliefs, to the bit, through either. The tracker
(constant-turn EKF per intruder) turns reports into beliefs; ``model: truth`` gives the
planner every intruder's exact state (the paper's setting).
"""

from __future__ import annotations

from collections.abc import Callable, Sequence

import numpy as np
from pymavlink.dialects.v20 import common as mavlink

from uavxai.avoidance.types import Intruder
from uavxai.bridges.framing import FrameReader
from uavxai.bridges.protocol import MessagePacker, new_codec
from uavxai.dynamics.environment import EnvironmentConfig
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.dynamics.state import TrafficState
from uavxai.scenario import Scenario
from uavxai.sim.episode import Episode, Observer
from uavxai.surveillance.adsb import Report, SurveillanceConfig, adsb_message, report_from_adsb
from uavxai.surveillance.tracker import SurveillancePicture, truth_beliefs

_STREAM = 0x53555256  # spawn key of the surveillance noise, apart from traffic and JSBSim


class AdsbLink:
    """ADS-B reports -> ADSB_VEHICLE frames -> decoded reports (what a receiver hands over).

    ``forward`` gets every packed frame too (the bridge's link to ground stations). ADS-B is
    not authenticated in the air either, so these frames are never signed.
    """

    def __init__(
        self,
        frame: LocalFrame,
        config: SurveillanceConfig,
        system_id: int = 1,
        forward: Callable[[bytes], None] | None = None,
    ) -> None:
        self.frame = frame
        self.config = config
        self._packer = MessagePacker(system_id, mavlink.MAV_COMP_ID_ADSB)
        self._reader = FrameReader(new_codec(None, 255, 0), stream=False)
        self._forward = forward
        self.decoded: list[Report] = []  # the last batch, as the planner's side decoded it

    def __call__(self, reports: Sequence[Report], t: float) -> list[Report]:
        if not reports:
            return []
        data = b"".join(self._packer.pack(adsb_message(r, self.frame)) for r in reports)
        if self._forward is not None:
            self._forward(data)
        parsed = self._reader.push(data)
        self.decoded = [
            report_from_adsb(m, self.frame, t, self.config)
            for m in parsed.messages
            if m.get_type() == "ADSB_VEHICLE"
        ]
        return self.decoded


class Picture(Observer):
    """The planner's picture of the traffic (an episode's ``picture``), fed every sample."""

    def __init__(self, scenario: Scenario, forward: Callable[[bytes], None] | None = None):
        self.config = SurveillanceConfig.from_scenario(scenario)
        seed = int(np.random.SeedSequence(scenario.seed, spawn_key=(_STREAM,)).generate_state(1)[0])
        wind = EnvironmentConfig.from_scenario(scenario).wind_enu[:2]  # tracked in the air mass
        self.surveillance = SurveillancePicture(self.config, seed, wind_mps=wind)
        frame = LocalFrame.from_origin(scenario.world.origin)
        self.link = AdsbLink(frame, self.config, scenario.bridge.system_id, forward)

    @property
    def truth(self) -> bool:
        return self.config.model == "truth"

    def on_start(self, ep: Episode) -> None:
        self.on_sample(ep, ep.state)

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        if self.truth:
            return
        reports = self.surveillance.sample(state)
        adsb = [r for r in reports if r.source == "adsb"]
        onboard = [r for r in reports if r.source != "adsb"]
        self.surveillance.ingest(self.link(adsb, state.t) + onboard)

    def __call__(self, state: TrafficState) -> list[Intruder]:
        if self.truth:
            return truth_beliefs(state)
        return self.surveillance.beliefs(state.t)
