"""The service-point search as a Gymnasium environment (paper section III-A).

The UAV starts at the centre of the users' region at h = 100 m and moves ``service.step_m`` per
step for ``service.steps`` steps inside the search box (the region in x, y; ``world.h`` in h),
choosing at each step one of 7 moves and a power level for every user.

- Observation ``(3 + K,)`` float32: the position scaled to [-1, 1] per axis, then the large-scale
  channel gain to each user in dB relative to free space at 100 m, divided by 10 (about -4..0).
  The observation carries the fading-free gains: small-scale fading decorrelates within
  centimetres, so a position decision rests on the large-scale gain a UAV estimates by averaging
  pilots; the reward, as in the paper, sees the instantaneous fading.
- Action ``MultiDiscrete([7] + [L] * K)``: a move (left -x, right +x, forward +y, back -y, up,
  down, hover) and a level ``l_k`` in ``0..L-1`` per user. Levels map to watts by
  ``levels_to_power``: ``p_k = P_max l_k / (L - 1)``, scaled down proportionally when the sum
  would exceed ``P_max``. Level 0 leaves the user unserved.
- Reward ``R(t) / 2^lambda`` in bit/s, lambda the number of users below the QoS rate. A move
  that would leave the search box is refused (the UAV stays) and the reward is halved once more,
  as if one more user had missed its QoS.
- Episodes never terminate; they are truncated after ``steps`` steps. The env remembers the best
  position visited (by the fading-free objective): that is the episode's service point.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from uavxai.comms.channel import Channel, free_space_loss_db
from uavxai.scenario import Scenario

START_ALTITUDE_M = 100.0
GAIN_REFERENCE_DISTANCE_M = 100.0
GAIN_FEATURE_DB_SCALE = 10.0
GAIN_FEATURE_CLIP = 10.0

MOVE_NAMES = ("left", "right", "forward", "back", "up", "down", "hover")
MOVES = np.array(
    [[-1, 0, 0], [1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1], [0, 0, 0]], dtype=float
)
HOVER = 6


def levels_to_power(levels: np.ndarray, p_max_w: float, power_levels: int) -> np.ndarray:
    """Watts for integer levels ``(..., K)``: ``P_max l / (L-1)``, scaled so ``sum <= P_max``."""
    levels = np.asarray(levels, dtype=float)
    total = levels.sum(axis=-1, keepdims=True)
    return p_max_w * levels / np.maximum(total, power_levels - 1)


@dataclass(frozen=True)
class SearchSpace:
    """The box the search flies in, its start and step; positions form a lattice around it."""

    lo: np.ndarray  # (3,) m
    hi: np.ndarray  # (3,) m
    start: np.ndarray  # (3,) m
    step_m: float

    @classmethod
    def from_scenario(cls, scenario: Scenario) -> SearchSpace:
        region, world = scenario.comms.users.region, scenario.world
        lo = np.array([region.x[0], region.y[0], world.h[0]], dtype=float)
        hi = np.array([region.x[1], region.y[1], world.h[1]], dtype=float)
        start = np.array(
            [np.mean(region.x), np.mean(region.y), np.clip(START_ALTITUDE_M, *world.h)]
        )
        return cls(lo=lo, hi=hi, start=start, step_m=float(scenario.service.step_m))

    def contains(self, position: np.ndarray) -> np.ndarray:
        eps = 1e-6 * self.step_m  # lattice points built by repeated addition land on the edge
        return np.all((position >= self.lo - eps) & (position <= self.hi + eps), axis=-1)

    def axes(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The lattice the moves can reach: ``start + i * step_m`` inside the box, per axis."""
        out = []
        for axis in range(3):
            below = np.floor((self.start[axis] - self.lo[axis]) / self.step_m + 1e-9)
            above = np.floor((self.hi[axis] - self.start[axis]) / self.step_m + 1e-9)
            out.append(self.start[axis] + self.step_m * np.arange(-below, above + 1))
        return out[0], out[1], out[2]

    def normalise(self, position: np.ndarray) -> np.ndarray:
        return 2.0 * (position - self.lo) / (self.hi - self.lo) - 1.0


def naive_placement(space: SearchSpace, users: np.ndarray, h_m: float = START_ALTITUDE_M):
    """The naive reference: above the users' centroid at 100 m (clamped to the box)."""
    x, y = users[:, :2].mean(axis=0)
    return np.clip(np.array([x, y, h_m]), space.lo, space.hi)


class ServiceEnv(gym.Env):
    """Service-point search; see the module docstring for spaces and reward."""

    metadata = {"render_modes": []}

    def __init__(self, channel: Channel, space: SearchSpace, steps: int, power_levels: int):
        self.channel = channel
        self.space = space
        self.steps = int(steps)
        self.power_levels = int(power_levels)
        k = channel.k
        self.action_space = gym.spaces.MultiDiscrete([len(MOVES)] + [power_levels] * k)
        low = np.concatenate([-np.ones(3), np.full(k, -GAIN_FEATURE_CLIP)]).astype(np.float32)
        self.observation_space = gym.spaces.Box(low=low, high=-low, dtype=np.float32)
        self._gain_ref_db = -free_space_loss_db(
            np.array(GAIN_REFERENCE_DISTANCE_M), channel.carrier_hz
        )
        naive = naive_placement(space, channel.users)
        # The naive objective sets the scale learners divide rewards by (about 1 near the
        # optimum, whatever the bandwidth, access mode or environment).
        self.naive_objective = float(channel.evaluate(naive, channel.equal_power()).objective)
        self.reward_scale = self.naive_objective if self.naive_objective > 0 else 1.0
        self.position = space.start.copy()
        self.t = 0
        self.path: list[np.ndarray] = []
        self.best: dict[str, Any] = {}

    @classmethod
    def from_scenario(cls, scenario: Scenario, users: np.ndarray | None = None) -> ServiceEnv:
        return cls(
            Channel.from_scenario(scenario, users),
            SearchSpace.from_scenario(scenario),
            scenario.service.steps,
            scenario.comms.power_levels,
        )

    # -------------------------------------------------------------------------- gym API
    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[np.ndarray, dict[str, Any]]:
        super().reset(seed=seed)
        self.position = self.space.start.copy()
        self.t = 0
        self.path = [self.position.copy()]
        self.best = {"objective": -np.inf, "position": self.position.copy(), "levels": None}
        return self._observe(), {"position": self.position.copy()}

    def step(self, action: np.ndarray) -> tuple[np.ndarray, float, bool, bool, dict[str, Any]]:
        action = np.asarray(action, dtype=np.int64)
        if action.shape != self.action_space.shape or not self.action_space.contains(action):
            raise ValueError(f"action {action.tolist()} is not in {self.action_space}")
        move, levels = int(action[0]), action[1:]
        target = self.position + MOVES[move] * self.space.step_m
        refused = not bool(self.space.contains(target))
        if not refused:
            self.position = target
        power = levels_to_power(levels, self.channel.p_max_w, self.power_levels)
        mean = self.channel.evaluate(self.position, power)
        faded = (
            mean
            if self.channel.fading == "none"
            else self.channel.evaluate(self.position, power, self.np_random)
        )
        reward = float(faded.objective) / (2.0 if refused else 1.0)
        if mean.objective > self.best["objective"]:
            self.best = {
                "objective": float(mean.objective),
                "position": self.position.copy(),
                "levels": levels.copy(),
            }
        self.t += 1
        self.path.append(self.position.copy())
        info = {
            "position": self.position.copy(),
            "power_w": power,
            "rate_bps": faded.rate_bps,
            "objective": float(mean.objective),
            "refused": refused,
        }
        return self._observe(), reward, False, self.t >= self.steps, info

    # -------------------------------------------------------------------------- helpers
    def _observe(self) -> np.ndarray:
        gain_db = 10.0 * np.log10(self.channel.mean_gain(self.position))
        features = np.clip(
            (gain_db - self._gain_ref_db) / GAIN_FEATURE_DB_SCALE,
            -GAIN_FEATURE_CLIP,
            GAIN_FEATURE_CLIP,
        )
        pos = np.clip(self.space.normalise(self.position), -1.0, 1.0)
        return np.concatenate([pos, features]).astype(np.float32)
