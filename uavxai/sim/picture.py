"""What the planner believes of the traffic: surveillance, the ADS-B link, the tracker.

Every sample the surveillance model (``surveillance:``) produces the reports due then: ADS-B
from cooperative intruders (rate, NACp/NACv noise, latency, dropouts) and the onboard
sensor's detections of the others. The ADS-B reports are packed as MAVLink ADSB_VEHICLE
frames and decoded back, as a companion computer receiving them would (:class:`Receiver`:
on the companion process beside the planner when ``uavxai run`` has one); in ``uavxai run``
the same frames also go out on the bridge's link, so a ground station shows the traffic the
planner sees and a real receiver could replace the simulated one. Both command paths pack and
decode alike, so a seed gives the same beliefs, to the bit, through either. The tracker
(constant-turn EKF per intruder) turns reports into beliefs; ``model: truth`` gives the
planner every intruder's exact state (the paper's setting). The receiver was on before the
episode (``surveillance.preroll_s``, :meth:`Picture.listen`), so the first picture is not empty.
"""

from __future__ import annotations

import math
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
from uavxai.sim.clock import Clock
from uavxai.sim.episode import EngineStep, Episode
from uavxai.sim.seat import TrafficReceiver
from uavxai.surveillance.adsb import (
    Report,
    Surveillance,
    SurveillanceConfig,
    adsb_message,
    report_from_adsb,
)
from uavxai.surveillance.emitters import TrafficCategories
from uavxai.surveillance.imm import ImmTrack
from uavxai.surveillance.tracker import Tracker, TrackerConfig, truth_beliefs

_STREAM = 0x53555256  # spawn key of the surveillance noise, apart from traffic and JSBSim


class Receiver:
    """The companion computer's side of surveillance: the ADSB_VEHICLE frames it receives,
    decoded back to reports, and the onboard sensor's detections, fed to the tracker.

    It runs where the planner runs: in the simulation's process, or on the companion
    process with the planner (:class:`uavxai.sim.companion.Companion`), which then decodes
    and tracks on its own core; it gets the same frames in the same order either way.
    """

    def __init__(self, scenario: Scenario) -> None:
        self.config = SurveillanceConfig.from_scenario(scenario)
        self.frame = LocalFrame.from_origin(scenario.world.origin)
        wind = EnvironmentConfig.from_scenario(scenario).wind_enu[:2]  # tracked in the air mass
        if self.config.tracker == "imm":
            self.tracker = Tracker(TrackerConfig.for_traffic(scenario), wind, track=ImmTrack)
        else:
            self.tracker = Tracker(wind_mps=wind)
        self._reader = FrameReader(new_codec(None, 255, 0), stream=False)
        self.decoded: list[Report] = []  # the last batch of ADS-B reports, as decoded here

    def receive(self, frames: bytes, onboard: Sequence[Report], t: float) -> None:
        """The frames and detections delivered at ``t``, into the tracker."""
        parsed = self._reader.push(frames).messages if frames else []
        self.decoded = [
            report_from_adsb(m, self.frame, t, self.config)
            for m in parsed
            if m.get_type() == "ADSB_VEHICLE"
        ]
        self.tracker.update([*self.decoded, *onboard])

    def beliefs(self, t: float) -> list[Intruder]:
        return self.tracker.beliefs(t)


class Picture(EngineStep):
    """The planner's picture of the traffic (an episode's ``picture``), fed every sample.

    The simulation's side measures (ADS-B from the cooperative intruders, the onboard
    sensor's detections) and packs the ADS-B reports as ADSB_VEHICLE frames (``forward``
    gets them too: the bridge's link to ground stations; ADS-B is not authenticated in the
    air either, so they are never signed); the ``receiver`` (a :class:`Receiver`, here or on
    the companion) decodes and tracks.
    """

    def __init__(
        self,
        scenario: Scenario,
        forward: Callable[[bytes], None] | None = None,
        receiver: TrafficReceiver | None = None,
    ) -> None:
        self.config = SurveillanceConfig.from_scenario(scenario)
        seed = int(np.random.SeedSequence(scenario.seed, spawn_key=(_STREAM,)).generate_state(1)[0])
        # the frames carry each aircraft's emitter category, the tracks keep it (issue 31)
        self.categories = TrafficCategories.from_scenario(scenario)
        self.surveillance = Surveillance(self.config, seed, self.categories)
        self.frame = LocalFrame.from_origin(scenario.world.origin)
        self._packer = MessagePacker(scenario.bridge.system_id, mavlink.MAV_COMP_ID_ADSB)
        self._forward = forward
        self.receiver: TrafficReceiver = receiver if receiver is not None else Receiver(scenario)

    @property
    def truth(self) -> bool:
        return self.config.model == "truth"

    def on_start(self, ep: Episode) -> None:
        self.listen(ep.state, ep.clock)
        self.on_sample(ep, ep.state)

    def listen(self, state: TrafficState, clock: Clock) -> None:
        """The receiver was on before the episode: it hears the traffic of ``state`` (t = 0)
        for ``surveillance.preroll_s`` before it, sample by sample on the episode's clock.

        We know where every aircraft is and how fast it flies at t = 0, not how it turned
        before, so each (the ownship too, for the onboard sensor's range and field of view)
        is flown back in a straight line along its velocity. The reports go through the same
        surveillance, frames and receiver as in flight, so their phases, noise and delivery
        carry on into t >= 0 as if the episode had started earlier. Once a decision period
        the receiver's picture is read, as the planner reads it in flight, so a track that
        falls silent drops on the same rule. Nothing goes to the ground stations: they would
        be shown the flown-back positions, stale and not flown by anyone, in one burst at t = 0.
        """
        if self.truth:
            return
        n = math.floor(self.config.preroll_s / clock.sample_s + 1e-9)
        for k in range(n, 0, -1):
            past = state.flown_straight(state.t - k * clock.sample_s)
            self._hear(past, None)
            if k % clock.samples_per_decision == 0:
                self.receiver.beliefs(past.t)

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        if not self.truth:
            self._hear(state, self._forward)

    def _hear(self, state: TrafficState, forward: Callable[[bytes], None] | None) -> None:
        """The reports due at ``state.t``, as frames to ``forward`` (if any) and the receiver."""
        reports = self.surveillance.observe(state)
        if not reports:
            return
        frames = b"".join(
            self._packer.pack(adsb_message(r, self.frame)) for r in reports if r.source == "adsb"
        )
        if frames and forward is not None:
            forward(frames)
        self.receiver.receive(frames, [r for r in reports if r.source != "adsb"], state.t)

    def __call__(self, state: TrafficState) -> list[Intruder]:
        if self.truth:
            return truth_beliefs(state, self.categories)
        return self.receiver.beliefs(state.t)
