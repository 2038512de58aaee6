"""What acts on a flight beside the planner and the mission, as engine steps of ``uavxai run``
(:class:`~uavxai.sim.episode.EngineStep`, run before every observer in the order the run
declares them): the battery (it turns a mission home at its reserve and ends it empty) and
the communication service (users walk, the delivered service is accounted, the service point
re-planned and the orbit moved).
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

from uavxai.dynamics.state import TrafficState
from uavxai.sim.episode import EngineStep, Episode
from uavxai.vocabulary import Outcome


class Energy(EngineStep):
    """The ownship's battery, fed every sample with the electrical power JSBSim's motor
    takes (plus the package's avionics and payload): energy (Wh), state of charge, and what
    a ground station shows (SYS_STATUS battery, VFR_HUD throttle). At the reserve a mission
    turns for home; an empty battery ends the episode (outcome ``battery``). Only worlds
    whose aircraft report power (JSBSim) have one."""

    def __init__(self) -> None:
        self.battery = None
        self.spec = None
        self.outcome = None

    def on_start(self, ep: Episode) -> None:
        from uavxai.dynamics.energy import Battery

        own = ep.world.powered_ownship()
        if own is None:
            return
        self._own = own
        self.spec = self._own.battery_spec()
        self.battery = Battery.from_spec(self.spec)
        power = self._own.electric_power_w()
        self.battery.draw(power, 0.0)
        self._report(ep, power)  # before the first telemetry goes out

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        if self.battery is None:
            return
        power = self._own.electric_power_w()
        self.battery.draw(power, ep.clock.sample_s)
        self._report(ep, power)
        if ep.mission is not None and self.battery.at_reserve:
            ep.mission.battery_reserve(ep)
        if self.battery.empty and ep.mission is not None:
            ep.mission.outcome = ep.mission.outcome or Outcome.BATTERY

    def _report(self, ep: Episode, power: float) -> None:
        """What SYS_STATUS and VFR_HUD carry: the pack's voltage under this load at this
        charge, the current, the charge left, the throttle."""
        shown = ep.path.power
        if shown is not None:
            current = self.spec.current_a(power)
            shown.voltage_v = self.spec.terminal_voltage_v(self.battery.soc, current)
            shown.current_a = current
            shown.soc = self.battery.soc
            shown.throttle = self._own.throttle()

    def section(self) -> dict:
        """``summary.energy``: what the battery gave and has left ({} without a battery)."""
        if self.battery is None:
            return {}
        return {
            "energy_wh": self.battery.energy_wh,
            "battery_soc_end": self.battery.soc,
            "capacity_wh": self.spec.capacity_wh,
            "reserve_soc": self.battery.reserve_soc,
        }

    def on_end(self, ep: Episode, summary: dict) -> None:
        if self.battery is not None:
            summary["energy"] = self.section()


def service_files(out: Path | None) -> list:
    """users.csv and service.csv in ``out``, their headers written ([] without ``out``)."""
    from uavxai.comms.delivery import SERVICE_COLUMNS, USERS_COLUMNS

    if out is None:
        return []
    files = [(out / "users.csv").open("w"), (out / "service.csv").open("w")]
    files[0].write(",".join(USERS_COLUMNS) + "\n")
    files[1].write(",".join(SERVICE_COLUMNS) + "\n")
    return files


class OrbitBreak:
    """Where the planned orbit would have had the aircraft while it avoids: the orbit flown on
    from the bearing at which avoiding began (the service lost to avoidance is measured
    against it)."""

    def __init__(self) -> None:
        self._break: tuple[float, float] | None = None  # (t, orbit bearing) when it began

    def planned(self, mission, t: float, pos: np.ndarray) -> tuple[np.ndarray | None, bool]:
        """(the planned orbit's point now, or None when not avoiding; whether avoiding)."""
        from uavxai.service.orbit_rate import orbit_bearing, orbit_position

        c = mission.config
        if mission.phase.value != "avoiding":
            self._break = None
            return None, False
        if self._break is None:
            self._break = (t, orbit_bearing(c.station, pos))
        t0, bearing0 = self._break
        at = orbit_position(c.station, c.radius_m, bearing0, t - t0, c.speed_mps, c.clockwise)
        return at, True


class Service(EngineStep):
    """The communication service, every sample: users walk (``comms.users.mobility``); while
    the mission serves (on station or avoiding) the rates delivered from the flown position
    are accounted with fading drawn per sample, and while avoiding, what the planned orbit
    would have delivered under the same fading (the service lost to avoidance). Writes
    ``users.csv`` and ``service.csv`` (README); re-plans the service point every
    ``service.replan_s`` and when a user drops below the QoS rate, moving the orbit.

    ``predicted_orbit_sum_rate_bps`` is what the placements in use promised: the orbit-mean
    sum rate (fading-free) about the service point with the plan's power and the users where
    the plan saw them (``orbit_average``, the number the planner's ``orbit_sum_rate_bps``
    reports), averaged over the same served samples as the delivered ``mean_sum_rate_bps``,
    so that a re-planned point counts for the time it was flown."""

    def __init__(
        self,
        scenario,
        channel,
        power_w,
        out: Path | None,
        replan=None,
        energy: Energy | None = None,
    ) -> None:
        from uavxai.comms.delivery import Delivery
        from uavxai.comms.mobility import UserMobility

        self.scenario = scenario
        self.channel = channel
        self.walk = UserMobility.from_scenario(scenario, users=channel.users)
        rng = np.random.default_rng([scenario.seed, 0x736572])  # the fading's own stream
        self.delivery = Delivery(channel, np.asarray(power_w, dtype=float), rng=rng)
        self.replan = replan  # (users (K,3)) -> (service point (3,), power (K,)), or None
        self.energy = energy  # the battery step, whose energy the bits are set against
        self.replan_s = scenario.service.replan_s
        self.qos_bps = float(scenario.comms.qos_rate_bps)
        self._last_plan_t = 0.0
        self._break = OrbitBreak()
        self._files = service_files(out)
        if self._files:
            self._users, self._service = self._files

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        from uavxai.comms.delivery import service_lines

        m, t, dt = ep.mission, state.t, ep.clock.sample_s
        users = self.walk.positions
        ep.sample_metrics["users_xyz"] = users
        ep.sample_metrics["qos_bps"] = self.qos_bps
        ep.sample_metrics["user_rates_bps"] = np.zeros(len(users))  # not served: grey
        if self._files:
            self._users.write(
                "".join(f"{t:.3f},{k},{u[0]:.3f},{u[1]:.3f}\n" for k, u in enumerate(users))
            )
        if m is not None and m.serving and m.outcome is None:  # each sample: the dt after it
            planned, avoiding = self._break.planned(m, t, state.pos[0])
            rows = self.delivery.sample(t, state.pos[0], users, dt, planned, avoiding)
            if self._files:
                self._service.write(service_lines(rows))
            rates = np.array([r[4] for r in rows])
            ep.sample_metrics["user_rates_bps"] = rates
            ep.sample_metrics["delivered_rate_bps"] = float(rates.sum())
            self._promised_bits += self._promise_bps * dt
            self._promised_s += dt
            self._maybe_replan(ep, users, rows)
        self.walk.advance(dt)

    def _maybe_replan(self, ep: Episode, users: np.ndarray, rows) -> None:
        if self.replan is None or not self.walk.moving:
            return
        t = ep.state.t
        due = self.replan_s is not None and t - self._last_plan_t >= self.replan_s
        qos = self.scenario.comms.qos_rate_bps
        # QoS drop judged on the mean channel, not one fading draw
        from uavxai.comms.delivery import rates_at

        _, mean = rates_at(self.channel, ep.state.pos[0], users, self.delivery.power_w)
        dropped = bool(np.any((mean[0] < qos) & (self.delivery.power_w > 0)))
        if not (due or (dropped and t - self._last_plan_t >= 10.0)):
            return
        self._last_plan_t = t
        point, power = self.replan(users)
        self.delivery.set_power(power)
        ep.mission.move_station(ep, point, "users moved" if due else "a user fell below QoS")
        self._promise(ep.mission.config, users)

    def _promise(self, c, users: np.ndarray) -> None:
        """What the plan in use promises: the orbit's mean sum rate, fading-free, about
        ``c.station`` with the current power, for the users where the plan saw them."""
        import dataclasses

        from uavxai.service.orbit_rate import orbit_average

        seen = dataclasses.replace(self.channel, users=np.asarray(users, dtype=float))
        avg = orbit_average(seen, c.station, c.radius_m, self.delivery.power_w)
        self._promise_bps = float(avg.sum_rate_bps)

    def on_start(self, ep: Episode) -> None:
        self._promise_bps, self._promised_bits, self._promised_s = math.nan, 0.0, 0.0
        if ep.mission is not None:
            self._promise(ep.mission.config, self.channel.users)

    def on_end(self, ep: Episode, summary: dict) -> None:
        if ep.mission is None:
            return
        mission = summary["mission"]  # the mission's section: the mission is an earlier step
        mission.update(self.delivery.summary())
        served = self._promised_s > 0  # else: the first plan's promise, never flown
        predicted = self._promised_bits / self._promised_s if served else self._promise_bps
        mission["predicted_orbit_sum_rate_bps"] = predicted
        section = self.energy.section() if self.energy is not None else {}
        energy = section.get("energy_wh")
        bits = mission.get("delivered_bits", 0.0)
        mission["energy_wh"] = energy
        mission["battery_soc_end"] = section.get("battery_soc_end")
        mission["bits_per_joule"] = bits / (energy * 3600.0) if energy else None

    def close(self) -> None:
        for f in self._files:
            f.close()
