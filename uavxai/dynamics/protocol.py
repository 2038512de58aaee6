"""What the episode engine needs of a world: the :class:`Dynamics` protocol that
:class:`uavxai.dynamics.world.JSBSimWorld` and :class:`uavxai.sim.kinematic.KinematicWorld`
implement (each declares it by its methods, not by inheritance)."""

from __future__ import annotations

from typing import TYPE_CHECKING, Protocol

from uavxai.dynamics.state import TrafficState

if TYPE_CHECKING:
    from uavxai.dynamics.aircraft import Aircraft


class Dynamics(Protocol):
    """What the engine needs of a world (JSBSimWorld, KinematicWorld)."""

    dt: float
    lost_intruders: list[str]  # intruders that failed in flight and were replaced, why

    def step(self, n: int = 1) -> None: ...
    def lookahead(self, ticks: int, every: int) -> int: ...
    def state(self) -> TrafficState: ...
    def command_ownship(
        self,
        bank_cmd_rad: float | None = None,
        accel_cmd_mps2: float | None = None,
        speed_target_mps: float | None = None,
        alt_target_m: float | None = None,
        speed_max_mps: float | None = None,
    ) -> None: ...
    def ownship_command(self) -> dict[str, float]: ...
    def powered_ownship(self) -> Aircraft | None:
        """The ownship's aircraft if its model reports electric power (JSBSim), else None."""
    def failure(self) -> str | None: ...
    def close(self) -> None: ...
