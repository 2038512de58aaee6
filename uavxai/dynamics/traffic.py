"""Initial conditions of the intruders, shared by the JSBSim world and the kinematic model so
that the same scenario and seed give the same traffic in both."""

from __future__ import annotations

import math

import numpy as np

from uavxai.errors import UserError
from uavxai.scenario import IntruderSpec, Scenario


def draw_intruders(
    scenario: Scenario, rng: np.random.Generator, count: int | None = None
) -> list[IntruderSpec]:
    """The scenario's explicit `intruders.list`, or `count` random intruders.

    Random intruders are uniform over the flight area, at least `min_start_distance_m`
    (horizontally) from the ownship's start, and from every fleet member's (a fleet's members
    start abreast; before, only member 0's start was kept clear: fleet-mission.yaml seed 43
    placed intruders 120 m from members 1 and 2), with uniform heading, speed and altitude from
    the scenario's ranges. Each keeps the scenario's default behaviour. One ownship draws the
    same numbers as before.
    """
    ic = scenario.intruders
    if ic.list is not None and count is None:
        return [
            s if s.behaviour else s.model_copy(update={"behaviour": ic.behaviour}) for s in ic.list
        ]
    n = ic.n if count is None else count
    w, starts = scenario.world, scenario.member_starts()
    specs: list[IntruderSpec] = []
    for _ in range(n):
        for _attempt in range(1000):
            x = rng.uniform(*w.x)
            y = rng.uniform(*w.y)
            if all(math.hypot(x - s.x, y - s.y) >= ic.min_start_distance_m for s in starts):
                break
        else:
            raise UserError(_no_room(scenario))
        specs.append(
            IntruderSpec(
                x=x,
                y=y,
                h=float(rng.uniform(*ic.altitude_m)),
                heading_deg=float(rng.uniform(0.0, 360.0)),
                speed_mps=float(rng.uniform(*ic.speed_mps)),
                behaviour=ic.behaviour,
            )
        )
    return specs


def _no_room(scenario: Scenario) -> str:
    """Why no random intruder could be placed, and what to change: the keys that fence off
    the starts (a fleet's members start `fleet.spacing_m` apart, each start fenced off)."""
    ic, w, n = scenario.intruders, scenario.world, scenario.fleet.size
    who = "the ownship's start"
    change = "a smaller intruders.min_start_distance_m"
    if n > 1:
        spacing = scenario.fleet.spacing_m
        who = f"each of the {n} fleet members' starts (fleet.spacing_m {spacing:g} m apart)"
        change += ", a smaller fleet.spacing_m or fleet.size"
    return (
        f"cannot place a random intruder at least intruders.min_start_distance_m "
        f"({ic.min_start_distance_m:g} m) from {who} inside the world (x {w.x[0]:g} ... "
        f"{w.x[1]:g} m, y {w.y[0]:g} ... {w.y[1]:g} m) in 1000 draws; set {change}, "
        "or a larger world.x / world.y"
    )
