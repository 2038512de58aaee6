"""A fleet in flight (issue 32, docs/fleet.md): members 1..N-1 of ``fleet.size`` ownships, each
flown by its own planner in an :class:`Episode` of its own inside the run's episode (whose
ownship is member 0), and the service the fleet delivers together.

A member's episode sees the one world through :class:`MemberWorld` (its own row first, its
commands to its own row), so the engine's pieces (``ownship_view``, the judge, the mission,
the battery) fly and judge it unchanged. :class:`Fleet`, an engine step of the run's episode,
decides every member at each decision and hands each member every sample;
:class:`FleetService` accounts each UAV's delivery to the users the fleet's placement gave it.
"""

from __future__ import annotations

import dataclasses
import itertools
import math
from collections.abc import Callable, Sequence
from pathlib import Path

import numpy as np

from uavxai.avoidance.types import Intruder
from uavxai.comms.delivery import jain_fairness
from uavxai.dynamics.state import TrafficState
from uavxai.geometry import turn_rate_of_bank
from uavxai.scenario import Scenario
from uavxai.sim.command import DirectPath
from uavxai.sim.episode import EngineStep, Episode, Observer
from uavxai.sim.mission import Mission, MissionConfig
from uavxai.sim.steps import Energy, OrbitBreak, service_files
from uavxai.surveillance.emitters import TrafficCategories
from uavxai.surveillance.tracker import truth_beliefs
from uavxai.vocabulary import Outcome

FLOOR_MARGIN_M = 20.0  # stations at least this far above the world's floor
# Two stations' layers: the NMAC height plus this much each member may stray from its
# station's height while it orbits in turbulence (docs/fleet.md, "Orbits kept apart")
HEIGHT_HOLD_M = 15.0


class MemberWorld:
    """Fleet row ``row`` of ``world`` (a :class:`uavxai.dynamics.world.JSBSimWorld`) as the
    member's own episode sees it: its row first, the others after in the world's order; its
    commands go to its row. The fleet steps the world; this view never does."""

    def __init__(self, world, row: int) -> None:
        self._world = world
        self.row = row
        self.scenario = world.scenario
        self.dt = world.dt
        self._seen: tuple[TrafficState, TrafficState] | None = None  # (world's, reordered)

    @property
    def lost_intruders(self) -> list[str]:
        """None here: the world's own episode (member 0's) reports the intruders lost (a new
        list each time, not one shared by every member's view)."""
        return []

    def state(self) -> TrafficState:
        s = self._world.state()
        if self._seen is None or self._seen[0] is not s:
            order = [self.row, *(r for r in range(s.n) if r != self.row)]
            mine = TrafficState(
                t=s.t,
                ids=tuple(s.ids[r] for r in order),
                pos=s.pos[order],
                vel=s.vel[order],
                att=s.att[order],
                airspeed=s.airspeed[order],
            )
            self._seen = (s, mine)
        return self._seen[1]

    def step(self, n: int = 1) -> None:
        raise RuntimeError("a fleet member's world is stepped by the run's episode")

    def lookahead(self, ticks: int, every: int) -> int:
        return 0  # a member never flies ahead: its flight depends on its commands

    def command_ownship(
        self,
        bank_cmd_rad: float | None = None,
        accel_cmd_mps2: float | None = None,
        speed_target_mps: float | None = None,
        alt_target_m: float | None = None,
        speed_max_mps: float | None = None,
    ) -> None:
        self._world.command_row(self.row, bank_cmd_rad, accel_cmd_mps2, speed_target_mps,
                                alt_target_m, speed_max_mps)  # fmt: skip

    def command_orbit(self, x: float, y: float, radius_m: float, clockwise: bool = True) -> None:
        self._world.command_member_orbit(self.row, x, y, radius_m, clockwise)

    def ownship_command(self) -> dict[str, float]:
        return self._world.aircraft[self.row].read_command()

    def powered_ownship(self):
        return self._world.aircraft[self.row]

    def failure(self) -> str | None:
        return self._world.failure()

    def close(self) -> None:
        pass  # the world is the run's


class IntentPicture:
    """A member's picture: the fleet's aircraft as they share themselves (exact state, and
    their intent, the turn their autopilot is commanded to fly: the chosen branch's first
    action, or the loiter law's bank, as the track's turn rate) and the intruders, whose turn
    is the one they fly now (non-cooperative): their exact state, or what ``traffic`` (member
    0's surveillance picture) believes of them. A fleet track less than ``layer_m`` from it in
    height (not in a layer of its own) also gets the fleet's clearance ``keep_m``
    (:func:`fleet_keep_m`). Only the planner reads it, and the planner flies a member only off
    its orbit (in transit, avoiding, returning): on their orbits the placement and the spacing
    keep members apart."""

    receiver = None  # the beliefs are formed here: member 0's planner never tracks onboard

    def __init__(
        self,
        world,
        keep_m: float = 0.0,
        layer_m: float = 0.0,
        traffic=None,
        categories: TrafficCategories | None = None,
    ) -> None:
        self._world = world
        self._keep_m = keep_m
        self._layer_m = layer_m
        self._traffic = traffic
        # each aircraft's emitter category, so that a member covers what an intruder (or
        # another member) can do by its own bank limit, as member 0's surveillance does
        self._categories = categories

    @property
    def truth(self) -> bool:
        return self._traffic is None or self._traffic.truth

    def __call__(self, state: TrafficState) -> list[Intruder]:
        w = self._world
        fleet = {w.ids[r]: r for r in w.fleet_rows}
        own_h = float(state.pos[0, 2])
        out = []
        for b in truth_beliefs(state, self._categories):
            row = fleet.get(str(b.id))
            if row is not None:
                bank = w.aircraft[row].read_command()["bank_cmd_rad"]
                speed = max(float(np.hypot(b.vx, b.vy)), 1.0)
                keep = self._keep_m if abs(b.h - own_h) < self._layer_m else 0.0
                b = dataclasses.replace(b, turn_rate=turn_rate_of_bank(bank, speed), keep_m=keep)
            elif self._traffic is not None:
                continue  # an intruder: surveillance's belief below
            out.append(b)
        if self._traffic is not None:  # its ADS-B tracks of the members give way to the above
            out += [b for b in self._traffic(state) if str(b.id) not in fleet]
        return out

    @classmethod
    def of(cls, scenario: Scenario, world, traffic=None) -> IntentPicture:
        """The picture a fleet member plans from, with the fleet's clearance and layers."""
        return cls(world, fleet_keep_m(scenario), orbit_separation(scenario).vertical_m, traffic,
                   TrafficCategories.from_scenario(scenario))  # fmt: skip


def fleet_keep_m(scenario: Scenario) -> float:
    """The clearance a member's planner keeps beyond ``d_min`` from another member not in a
    layer of its own (docs/fleet.md, "Kept apart in transit"): the smallest sphere that holds
    the NMAC cylinder (its radius the cylinder's corner, hypot(152.4, 30.48) = 155.4 m), no
    more: members orbiting neighbouring homes come 158 m near (``fleet.spacing_m`` 370 m less
    two 106 m radii), and a larger sphere put a member avoiding at home in conflict with its
    neighbour's orbit on every branch (round 5: fleet.yaml seeds 16 and 18 left the world
    there, 44 m from its edge); never negative."""
    a = scenario.avoidance
    return max(float(np.hypot(a.nmac.horizontal_m, a.nmac.vertical_m)) - a.d_min_m, 0.0)


# Member j's command path over its view of the world (``uavxai.sim.run.member_paths``: MAVLink
# system ``bridge.system_id + j``); None: the direct path onto its row
MemberPath = Callable[[int, MemberWorld], object] | None
# What watches member j's episode (its decisions.jsonl, its part of the recording), made for it
MemberObserver = Callable[[int], Observer]


class Member:
    """Fleet member ``j`` (1-based) of the world: its episode, mission and battery."""

    def __init__(
        self, scenario: Scenario, world, j: int, station, planner, max_steps: int,
        path: MemberPath = None, observers: Sequence[MemberObserver] = (),
    ) -> None:  # fmt: skip
        from uavxai.sim.build import start_episode

        self.j = j
        start = scenario.member_starts()[j]
        own = scenario.ownship.model_copy(update={"start": start})
        config = MissionConfig.from_scenario(scenario.model_copy(update={"ownship": own}), station)
        view = MemberWorld(world, world.member_rows[j - 1])
        path = DirectPath(view) if path is None else path(j, view)
        self.mission = Mission(config, path.announce)
        self.mission.home_orbit = True  # done on reaching its hold orbit (docs/fleet.md)
        self.energy = Energy()
        self.outcome: Outcome | None = None
        self._closed, self._counters = False, None
        self.ep = start_episode(
            scenario, view, planner, path, config.station, max_steps=max_steps,
            picture=IntentPicture.of(scenario, world),
            mission=self.mission,
            engine_steps=[self.mission, self.energy],
            observers=[make(j) for make in observers],
        )  # fmt: skip

    @property
    def flying(self) -> bool:
        return self.outcome is None

    def sample(self) -> Outcome | None:
        """Judge the sample just flown; the member's outcome when it changes now. A member
        done holds at home (``Mission.hold_home``: the orbit re-sent every decision, so its
        bridge's command watchdog never levels its wings and sends it out of the world, as a
        single orbit command did), judged on as long as the fleet flies: a collision, failure
        or exit after it is done still ends the fleet."""
        _, outcome = self.ep.sample()
        if outcome is None or outcome is self.outcome:
            return None
        self.outcome = outcome
        if outcome is Outcome.COMPLETED:
            self.mission.hold_home()
        return outcome

    def close(self) -> dict[str, int] | None:
        """Close the member's command path (its bridge and link) and its observers (their
        files) once; its link's counters (None: the direct path)."""
        if not self._closed:
            self._closed, self._counters = True, self.ep.path.close()
            for o in self.ep.observers:
                o.close()
        return self._counters

    def entry(self, fleet_outcome: str) -> dict:
        """The member's ``summary.fleet`` object (delivery added by the service)."""
        ep = self.ep
        return {
            "id": ep.state.ids[0],
            "outcome": self.outcome.value if self.outcome is not None else fleet_outcome,
            "min_separation_m": ep.min_separation_m,
            "nmac": ep.nmac,
            "decisions": ep.steps,
            "energy_wh": self.energy.section().get("energy_wh"),
            "phases": self.mission.phases,
            "station": list(self.mission.config.station),
        }


class Fleet(EngineStep):
    """The fleet's members beside the run's ownship (member 0): at each of its decisions every
    member still flying decides, from its own picture, with its own planner; every sample each
    member is judged. A member's collision, failure or exit ends everyone's episode with that
    outcome; the fleet completes when every UAV has (the ownship, done first, waits for the
    others orbiting its home, as the members do: nothing more is served)."""

    def __init__(
        self,
        scenario: Scenario,
        stations: np.ndarray,
        planner: Callable[[int], object],
        max_steps: int,
        path: MemberPath = None,
        observers: Sequence[MemberObserver] = (),
    ) -> None:
        self.scenario = scenario
        self.stations = np.asarray(stations, dtype=float)
        self._planner = planner  # member j -> its planner, seeded
        self._max_steps = max_steps
        self._path = path
        self._observers = observers  # each member's, made for it when it starts
        self.members: list[Member] = []
        self._waiting = False

    def on_start(self, ep: Episode) -> None:
        # member 0 plans as the members do: their shared state, intent and clearance, and its
        # own surveillance of the intruders (the picture it had; still fed as an engine step)
        ep.picture = IntentPicture.of(self.scenario, ep.world, traffic=ep.picture)
        ep.mission.home_orbit = True  # done on reaching its hold orbit, as the members
        for j in range(1, len(self.stations)):
            m = Member(self.scenario, ep.world, j, self.stations[j], self._planner(j),
                       self._max_steps, self._path, self._observers)  # fmt: skip
            self.members.append(m)  # before it begins: closed whatever happens
            m.ep.begin()

    def episodes(self, ep: Episode) -> list[Episode]:
        """Each UAV's episode, member 0 (the run's) first."""
        return [ep, *(m.ep for m in self.members)]

    def uavs(self, ep: Episode) -> list[tuple[Mission, int]]:
        """Each UAV's mission and world row, member 0 first."""
        return [(ep.mission, 0)] + [(m.mission, m.ep.world.row) for m in self.members]

    def on_decision(self, ep: Episode, event) -> None:
        for m in self.members:  # flying or holding at home
            m.ep.decide()

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        main = ep.mission
        for m in self.members:
            ended = m.sample()
            if ended is not None and ended is not Outcome.COMPLETED:
                main.outcome = ended  # the fleet's episode ends with it
        others = any(m.flying for m in self.members)
        if self._waiting and not others and main.outcome is None:  # the last one is done
            main.outcome = Outcome.COMPLETED
        elif main.outcome is Outcome.COMPLETED and others:  # member 0 done first: it waits
            main.outcome = None
            if not self._waiting:
                self._waiting = True
                main.hold_home()

    def on_end(self, ep: Episode, summary: dict) -> None:
        own = {
            "id": ep.state.ids[0],
            "outcome": summary["outcome"],
            "min_separation_m": summary["min_separation_m"],
            "nmac": summary["nmac"],
            "decisions": ep.steps,
            "energy_wh": (summary.get("energy") or {}).get("energy_wh"),
            "phases": ep.mission.phases,
            "station": list(ep.mission.config.station),
        }
        summary["fleet"] = [own, *(m.entry(summary["outcome"]) for m in self.members)]
        for entry, m in zip(summary["fleet"][1:], self.members, strict=True):
            counters = m.close()
            if counters is not None:  # its bridge's, as summary.bridge is member 0's
                entry["bridge"] = counters

    def close(self) -> None:
        for m in self.members:
            m.close()


class FleetService(EngineStep):
    """The fleet's service every sample: the whole crowd walks once; each UAV serving (on
    station or avoiding) delivers to its own users (the placement's association) through its
    one-UAV channel (``FleetChannel.uav_channel``: exact in OFDMA; in the shared band with the
    other UAVs' interference as planned), fading drawn per UAV from its own stream. Writes
    users.csv and service.csv (with ``uav``); adds each UAV's ``delivered_bits`` and
    ``users_served`` to ``summary.fleet`` and the fleet's totals to ``summary.mission``.

    A member leaving early (its battery's reserve, or ``fleet.leave``; docs/fleet.md, "A member
    leaving early"): the members still to serve are re-planned for the whole crowd where it
    now is (:func:`fleet_stations` with their number), each flown to the new station nearest
    it, and serve the new association from then on; ``summary.fleet_departures`` says who left
    when, which UAV served whom before and after, and the QoS share of the departed member's
    users (and of the crowd) before and after."""

    def __init__(self, scenario: Scenario, channel, plan, fleet: Fleet, out: Path | None) -> None:
        from uavxai.comms.mobility import UserMobility

        self.scenario, self.channel, self.fleet = scenario, channel, fleet
        self.walk = UserMobility.from_scenario(scenario, users=channel.users)
        n = len(plan.positions)
        self.mine = [np.flatnonzero(plan.association == i) for i in range(n)]
        self.first_mine = list(self.mine)
        self.delivery = self._deliveries(channel, plan, list(range(n)), ())
        self.spent: list[list] = [[] for _ in range(n)]  # each UAV's deliveries of past plans
        self._breaks = [OrbitBreak() for _ in self.mine]
        self.qos_bps = float(scenario.comms.qos_rate_bps)
        self._leave = scenario.fleet.leave
        self._gone: list[int] = []  # the UAVs that left early, in order
        self.departures: list[dict] = []
        self.tally = QosTally(len(channel.users), self.qos_bps)
        self.bits = np.zeros(len(channel.users))  # each user's delivered bits, whichever UAV
        self._began: dict[int, tuple] = {}  # the tally when each UAV began to serve
        self._marks: list[tuple] = []  # each departure's (its UAV's start, the departure)
        self._files = service_files(out)
        if self._files:
            self._users, self._service = self._files

    def _deliveries(self, channel, plan, uavs: list[int], stream: tuple[int, ...]) -> list:
        """A :class:`Delivery` for each of ``uavs``, plan UAV i serving as fleet UAV
        ``uavs[i]`` (its fading from its own stream; ``stream`` apart for each re-plan)."""
        from uavxai.comms.delivery import Delivery
        from uavxai.comms.fleet import FleetChannel

        fc = FleetChannel.of(channel, len(plan.positions))
        gains = fc.gains(plan.positions)
        return [
            Delivery(
                fc.uav_channel(i, gains, plan.association, plan.power_w),
                plan.power_w[plan.association == i],
                rng=np.random.default_rng([self.scenario.seed, 0x736572, n, *stream]),
            )
            for i, n in enumerate(uavs)
        ]

    def on_sample(self, ep: Episode, state: TrafficState) -> None:
        from uavxai.comms.delivery import service_lines

        self._departures(ep, state)
        t, dt = state.t, ep.clock.sample_s
        users = self.walk.positions
        if self._files:
            self._users.write(
                "".join(f"{t:.3f},{k},{u[0]:.3f},{u[1]:.3f}\n" for k, u in enumerate(users))
            )
        rates, serving = np.zeros(len(users)), np.zeros((len(users), 3))
        anyone = False
        for n, (mission, row) in enumerate(self.fleet.uavs(ep)):
            mine, pos = self.mine[n], state.pos[row]
            serving[mine] = pos
            if not (mission.serving and mission.outcome is None):
                continue
            anyone = True
            if n not in self._began:
                self._began[n] = self.tally.mark()
            planned, avoiding = self._breaks[n].planned(mission, t, pos)
            rows = self.delivery[n].sample(t, pos, users[mine], dt, planned, avoiding)
            rates[mine] = [r[4] for r in rows]
            if self._files:
                self._service.write(service_lines(rows, n, mine))
        self.bits += rates * dt
        if anyone:  # the QoS shares before and after a departure
            self.tally.add(rates)
            for d in self.departures:
                mine = np.array(d["users"], dtype=np.int64)
                # a member that served nobody leaves no one to re-cover: it stays None
                if (d["recovered_after_s"] is None and mine.size
                        and np.all(rates[mine] >= self.qos_bps)):  # fmt: skip
                    d["recovered_after_s"] = round(t - d["t"], 3)
        # what the recording draws (the run's Service sets the same for one UAV): every user,
        # its rate now (0: its UAV is not serving), and its UAV, where the link is drawn from
        ep.sample_metrics.update(users_xyz=users.copy(), qos_bps=self.qos_bps,
                                 user_rates_bps=rates, user_uav_xyz=serving)  # fmt: skip
        if ep.mission.serving:
            ep.sample_metrics["delivered_rate_bps"] = float(rates[self.mine[0]].sum())
        self.walk.advance(dt)

    def _departures(self, ep: Episode, state: TrafficState) -> None:
        """The scripted leave when due; every UAV that has left early since the last sample
        re-covered by the others."""
        episodes = self.fleet.episodes(ep)
        if self._leave is not None and state.t >= self._leave.at_s - 1e-9:
            e = episodes[self._leave.member]
            e.mission.leave(e, f"fleet.leave at {self._leave.at_s:g} s")
        for n, e in enumerate(episodes):
            if e.mission.left is not None and n not in self._gone:
                self._gone.append(n)
                self._recover(episodes, n, e.mission.left, state)

    def _recover(self, episodes: list[Episode], n: int, why: str, state: TrafficState) -> None:
        """UAV ``n`` has left: the UAVs still to serve (in transit or on station) re-planned
        for the whole crowd where it is now, each to the new station nearest it."""
        from uavxai.sim.mission import Phase

        users = self.walk.positions
        before = self.association()
        stay = [
            m for m, e in enumerate(episodes)
            if m not in self._gone and e.mission.outcome is None and not e.mission.holding
            and e.mission.phase is not Phase.RETURNING
        ]  # fmt: skip
        record = {"uav": n, "t": round(state.t, 3), "why": why,
                  "users": [int(k) for k in self.mine[n]],
                  "association_before": before.tolist(),
                  "recovered_after_s": None}  # fmt: skip
        self._marks.append((self._began.get(n), self.tally.mark()))
        self.mine[n] = np.zeros(0, dtype=np.int64)  # it serves no one from now on
        if stay:
            seen = dataclasses.replace(self.channel, users=np.asarray(users, dtype=float))
            plan = fleet_stations(self.scenario, users, size=len(stay))
            rows = [episodes[m].state.pos[0] for m in stay]
            order = nearest_stations(np.array(rows), plan.positions)
            plan = dataclasses.replace(
                plan,
                positions=plan.positions[order],
                association=np.argsort(order)[plan.association],
            )  # plan UAV i is now stay[i]'s
            fresh = self._deliveries(seen, plan, stay, (len(self._gone),))
            for i, m in enumerate(stay):
                self.spent[m].append(self.delivery[m])
                self.delivery[m] = fresh[i]
                self.mine[m] = np.flatnonzero(plan.association == i)
                e = episodes[m]
                e.mission.move_station(e, plan.positions[i], f"UAV {n} left: its users re-covered",
                                       fly_there=True)  # fmt: skip
            record["stations_after"] = {str(m): plan.positions[i].tolist() for i, m in
                                        enumerate(stay)}  # fmt: skip
        record["association_after"] = self.association().tolist()
        self.departures.append(record)

    def association(self) -> np.ndarray:
        """Each user's UAV now (-1: none)."""
        out = np.full(self.walk.positions.shape[0], -1, dtype=np.int64)
        for n, mine in enumerate(self.mine):
            out[mine] = n
        return out

    def on_end(self, ep: Episode, summary: dict) -> None:
        total = 0.0
        for n, entry in enumerate(summary["fleet"]):
            bits = sum(float(d.summary().get("delivered_bits", 0.0))
                       for d in [*self.spent[n], self.delivery[n]])  # fmt: skip
            entry["delivered_bits"] = bits
            entry["users_served"] = [int(k) for k in self.first_mine[n]]
            if self._gone:  # the association changed: whom it serves at the end
                entry["users_served_after"] = [int(k) for k in self.mine[n]]
            total += bits
        mission = summary.setdefault("mission", {})
        mission["delivered_bits"] = total
        # the crowd's: each user's bits from whichever UAV served it, their Jain fairness, and
        # the QoS share over every sample in which any UAV served (a user none serves below it)
        mission["delivered_bits_per_user"] = [float(b) for b in self.bits]
        mission["jain_fairness"] = jain_fairness(self.bits)
        mission["qos_user_seconds_share"] = self.tally.share((0.0, 0), self.tally.mark())[0]
        if self._gone or self._leave is not None:
            summary["fleet_departures"] = [
                self._shares(d, *marks) for d, marks in zip(self.departures, self._marks,
                                                            strict=True)
            ]  # fmt: skip

    def _shares(self, record: dict, began, left) -> dict:
        """The QoS share of the departed UAV's users and of the whole crowd (:class:`QosTally`):
        before, from when the departed UAV began to serve (``began``; None: it never did) to
        its departure (``left``); after, from the departure to the last sample anyone
        served."""
        users = np.array(record["users"], dtype=np.int64)
        end = self.tally.mark()
        windows = {"before": (began, left), "after": (left, end)}
        out = dict(record)
        for name, (since, until) in windows.items():
            share, samples = self.tally.share(since, until, users)
            out[f"qos_share_{name}"] = share
            out[f"crowd_qos_share_{name}"] = self.tally.share(since, until)[0]
            out[f"samples_{name}"] = samples
        return out

    def close(self) -> None:
        for f in self._files:
            f.close()


class QosTally:
    """User-samples at or above the QoS rate, over the samples in which any UAV serves (a user
    no UAV serves counting as below it): running totals, so the share between two marks is a
    difference, in memory of the crowd's size however long the mission."""

    def __init__(self, k: int, qos_bps: float) -> None:
        self.qos_bps = qos_bps
        self.hits = np.zeros(k)  # each user's samples at QoS so far
        self.samples = 0

    def add(self, rates: np.ndarray) -> None:
        self.hits += rates >= self.qos_bps
        self.samples += 1

    def mark(self) -> tuple[np.ndarray, int]:
        return self.hits.copy(), self.samples

    def share(self, since, until, users: np.ndarray | None = None) -> tuple[float | None, int]:
        """(the share of ``users``' samples at QoS between two marks, or None if there were
        none; the samples); ``since`` None: an empty window."""
        if since is None:
            return None, 0
        hits, samples = until[0] - since[0], until[1] - since[1]
        if users is not None:
            hits = hits[users]
        if samples == 0 or hits.size == 0:
            return None, samples
        return float(hits.sum() / (hits.size * samples)), samples


def nearest_stations(at: np.ndarray, stations: np.ndarray) -> np.ndarray:
    """Which station each UAV flies to: the assignment of ``stations`` (N, 3) to UAVs at
    ``at`` (N, 3) with the least total horizontal distance (every order tried: N <= 8), so a
    re-plan moves each UAV as little as the fleet allows; ``order[i]``: UAV i's station."""
    best, order = math.inf, None
    for perm in itertools.permutations(range(len(stations))):
        d = float(np.hypot(*(stations[list(perm), :2] - at[:, :2]).T).sum())
        if d < best - 1e-9:
            best, order = d, perm
    return np.array(order, dtype=np.int64)


def fleet_stations(scenario: Scenario, users: Sequence, size: int | None = None) -> object:
    """The joint placement of ``size`` UAVs (the fleet's, ``fleet.size``, unless fewer are
    left to serve) for ``users`` on the scenario's channel and lattice
    (:func:`uavxai.service.fleet.plan_fleet`, fading-free): each UAV's station, the user
    association and the power (a :class:`uavxai.service.fleet.FleetPlan`)."""
    size = scenario.fleet.size if size is None else size
    from uavxai.comms.channel import Channel
    from uavxai.comms.fleet import FleetChannel
    from uavxai.service.fleet import FleetProblem, plan_fleet
    from uavxai.service.service_env import SearchSpace

    channel = Channel.from_scenario(scenario, users=np.asarray(users, dtype=float))
    space = SearchSpace.from_scenario(scenario)
    # a station at the world's floor is left at the first gust's dip (fleet.yaml, seed 3:
    # two members placed at 50 m flew out of the world at 32 s)
    floor = min(space.lo[2] + FLOOR_MARGIN_M, space.hi[2])
    space = dataclasses.replace(space, lo=np.array([*space.lo[:2], floor]))
    sep = check_homes(scenario)
    problem = FleetProblem(
        FleetChannel.of(channel, size), space, scenario.comms.power_levels, sep
    )
    try:
        return plan_fleet(problem)
    except ValueError as e:  # the separation does not fit in the users' region
        from uavxai.errors import UserError

        raise UserError(
            f"fleet.size = {size}: the members' stations cannot be kept apart "
            f"in comms.users.region and world.h ({e}); allowed: fewer UAVs, a larger region "
            "or a taller world"
        ) from e


def check_homes(scenario: Scenario):
    """Refuse homes (the members' starts) the fleet cannot orbit safely (docs/fleet.md, "The
    homes"), and return the stations' separation (:func:`orbit_separation`). Members done orbit
    their homes at one height, so the homes are at least the stations' horizontal separation
    apart (``fleet.spacing_m``); and each home orbit stays at least that far, one turn diameter
    + the NMAC horizontal distance, inside every edge of the world: room for a member avoiding
    there to turn about without leaving it (fleet.yaml's homes, 44 m inside the west edge, were
    every out-of-bounds of rounds 1-6)."""
    from uavxai.dynamics.orbit import scenario_orbit_radius
    from uavxai.errors import UserError

    sep = orbit_separation(scenario)
    need = sep.horizontal_m
    if scenario.fleet.spacing_m < need:  # the homes are orbited too, at one height
        raise UserError(
            f"fleet.spacing_m {scenario.fleet.spacing_m:g} m: members done orbit their homes "
            f"(their starts, abreast at one height) and would meet; allowed: at least "
            f"{need:.0f} m (twice the orbit radius + the NMAC horizontal distance)"
        )
    r, w = scenario_orbit_radius(scenario), scenario.world
    for i, s in enumerate(scenario.member_starts()):
        edge = min(s.x - w.x[0], w.x[1] - s.x, s.y - w.y[0], w.y[1] - s.y) - r
        if edge < need:
            raise UserError(
                f"fleet.size = {scenario.fleet.size}: member {i}'s home ({s.x:.0f}, {s.y:.0f}) "
                f"is orbited (radius {r:.0f} m) {edge:.0f} m from the edge of the world x "
                f"{list(w.x)}, y {list(w.y)}; allowed: at least {need:.0f} m (one turn "
                "diameter + the NMAC horizontal distance): ownship.start farther from the "
                "edges, a smaller fleet.spacing_m or a larger world"
            )
    return sep


def orbit_separation(scenario: Scenario):
    """How far apart the members' stations are kept (docs/fleet.md, "Orbits kept apart"): two
    UAVs each on its orbit of radius r about stations d apart come as near as d - 2r, so
    stations at least 2r + the NMAC horizontal distance apart never meet in the NMAC cylinder
    whatever the orbits' phases; or, a layer of their own, at least the NMAC height plus
    twice ``HEIGHT_HOLD_M`` apart in height."""
    from uavxai.dynamics.orbit import scenario_orbit_radius
    from uavxai.service.fleet import Separation

    nmac = scenario.avoidance.nmac
    return Separation(
        horizontal_m=2.0 * scenario_orbit_radius(scenario) + nmac.horizontal_m,
        vertical_m=nmac.vertical_m + 2.0 * HEIGHT_HOLD_M,
    )
