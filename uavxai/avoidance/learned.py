"""Learned avoidance baselines: DQN and Safe-DQN (the paper's learned comparisons).

Both see the same intruder-count-independent observation, the one of
:mod:`uavxai.avoidance.observation` (goal bearing and distance, speed, bank, the nearest wall;
the ``n_nearest`` intruders, nearest first, relative position and velocity in the ownship's
heading frame, zero-padded with a ``present`` flag, and each one's closest point of approach),
so 3 or 40 intruders give the same vector; the Gymnasium env they are trained on returns it.

- **DQN**: one Q-network over the 9 actions, trained on the sum of the goal and safety rewards
  (see :mod:`uavxai.learning.train`); acts greedily.
- **Safe-DQN** (after Wang et al. 2022, "Explainable and safe reinforcement learning for
  autonomous air mobility"): two Q-networks, one for the goal reward (progress, arrival) and
  one for the safety reward (separation loss, collision, leaving the area). It acts with the
  best sum ``Q_goal + Q_safety`` among the actions whose ``Q_safety`` is at least the median
  over the 9 actions, so an action the safety network distrusts is never taken for speed.

Each decision reports, per action, the network's Q (Safe-DQN: the sum, with the parts in the
explanation) and the minimum separation the encounter model predicts for that action held for
``action_hold_s`` with the intruders at constant velocity, so that the learned planners'
explanations can be checked against the same physics as the tree search's.
"""

from __future__ import annotations

import math
import time
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import torch
from torch import nn

from uavxai.avoidance.lines import flies, measure_line, with_measure
from uavxai.avoidance.mcts import intruder_arrays
from uavxai.avoidance.model import (
    PHI_CMD,
    EncounterModel,
    accel_command,
    bank_command,
    ownship_state,
)
from uavxai.avoidance.observation import N_NEAREST, observation_size, observe
from uavxai.avoidance.types import (
    N_ACTIONS,
    ChildStats,
    Decision,
    Goal,
    Intruder,
    Ownship,
    PlannerConfig,
    action_name,
    check_plan_inputs,
)
from uavxai.errors import CheckpointError, short_repr
from uavxai.learning import checkpoint
from uavxai.paths import avoidance_checkpoints_dir

ALGOS = ("dqn", "safe_dqn")


def obs_dim(n_nearest: int = N_NEAREST) -> int:
    return observation_size(n_nearest)


# A fixed encounter whose observation a checkpoint stores: if the observation code changes
# after training (scales, order), loading the checkpoint says so instead of acting on garbage.
def _probe_observation(n_nearest: int) -> np.ndarray:
    config = PlannerConfig()
    state = np.array([400.0, 600.0, 120.0, 20.0, 0.7, 0.1, 0.17])
    pos = np.array([[700.0, 900.0, 110.0], [380.0, 450.0, 135.0], [1500.0, 200.0, 100.0]])
    vel = np.array([[-15.0, -10.0, 0.0], [3.0, 22.0, 0.5], [0.0, 25.0, 0.0]])
    return observe(state, pos, vel, np.array([1000.0, 1000.0, 100.0]), config, n_nearest)


# ------------------------------------------------------------------------------------ networks
class QNetwork(nn.Module):
    """An MLP from the observation to one Q-value per action."""

    def __init__(self, n_obs: int, hidden: Sequence[int] = (256, 256)) -> None:
        super().__init__()
        layers: list[nn.Module] = []
        width = n_obs
        for h in hidden:
            layers += [nn.Linear(width, h), nn.ReLU()]
            width = h
        layers.append(nn.Linear(width, N_ACTIONS))
        self.net = nn.Sequential(*layers)

    def forward(self, obs: torch.Tensor) -> torch.Tensor:
        return self.net(obs)


def safe_action(q_goal: torch.Tensor, q_safety: torch.Tensor) -> torch.Tensor:
    """Safe-DQN's choice per row: the best ``Q_goal + Q_safety`` among the actions whose
    ``Q_safety`` is at least that row's median (lower median: 5 of the 9 actions pass)."""
    median = q_safety.median(dim=-1, keepdim=True).values
    total = torch.where(q_safety >= median, q_goal + q_safety, -torch.inf)
    return total.argmax(dim=-1)


def head_names(algo: str) -> tuple[str, ...]:
    """The Q-networks an algorithm learns, in checkpoint order."""
    return ("q",) if algo == "dqn" else ("goal", "safety")


# --------------------------------------------------------------------------------- checkpoints
def save_checkpoint(
    path: Path,
    algo: str,
    nets: dict[str, QNetwork],
    *,
    hidden: Sequence[int],
    n_nearest: int,
    meta: dict,
) -> None:
    """``model.pt``: the networks' weights and what is needed to rebuild and feed them
    (:func:`uavxai.learning.checkpoint.save`)."""
    checkpoint.save(
        path,
        "avoidance",
        {
            "algo": algo,
            "n_nearest": int(n_nearest),
            "obs_dim": obs_dim(n_nearest),
            "obs_probe": torch.as_tensor(_probe_observation(n_nearest)),
            "hidden": [int(h) for h in hidden],
            "state_dicts": {k: net.state_dict() for k, net in nets.items()},
            "meta": meta,
        },
    )


def shipped_checkpoint(algo: str) -> Path:
    return avoidance_checkpoints_dir() / f"{algo}.pt"


def load_checkpoint(path: str | Path | None, algo: str) -> tuple[dict[str, QNetwork], dict]:
    """The networks of a checkpoint for ``algo`` (None: the shipped one), in eval mode.

    Read by :mod:`uavxai.learning.checkpoint` (bounded, CRC-checked, weights only, every
    declared size bounded and compared with the stored tensors before a network is built);
    then it must be made for ``algo`` and for this uavxai's observation. Any problem is a
    :class:`CheckpointError` naming the file, the field and what is allowed.
    """
    if algo not in ALGOS:
        raise CheckpointError(f"unknown learned avoidance algorithm '{algo}'; known: {ALGOS}")
    p = Path(path) if path is not None else shipped_checkpoint(algo)
    where = "avoidance.checkpoint" if path is not None else "the shipped checkpoint"
    retrain = f"`uavxai train SCENARIO --stage avoidance --algo {algo}`"
    if not p.is_file():
        raise CheckpointError(
            f"{where} {p}: no such file; train one with {retrain[:-1]} --out DIR` and point "
            "avoidance.checkpoint at DIR/model.pt."
        )
    src = checkpoint.Source(p, where, f"Use a model.pt written by {retrain}.")
    ckpt = checkpoint.read(src, "avoidance")
    if ckpt.get("algo") != algo:
        raise src.error(
            f"trained for {short_repr(ckpt.get('algo'))}, but the planner is '{algo}'; use a "
            f"checkpoint trained with --algo {algo}."
        )
    n_nearest, hidden = _checked_sizes(ckpt, src)
    n_obs = obs_dim(n_nearest)
    _check_observation(ckpt, n_nearest, n_obs, src)
    state_dicts = ckpt.get("state_dicts")
    if not isinstance(state_dicts, dict):
        raise src.bad("state_dicts", state_dicts, f"one state dict per network {head_names(algo)}")
    nets = {
        name: checkpoint.build_checked(
            lambda: QNetwork(n_obs, hidden),
            state_dicts.get(name),
            src,
            name,
            sizes=f"hidden {hidden} and {n_obs} inputs",
        )
        for name in head_names(algo)
    }
    info = {"n_nearest": n_nearest, "hidden": hidden, **checkpoint.declared_meta(ckpt, src)}
    return nets, info


def _checked_sizes(ckpt: dict, src: checkpoint.Source) -> tuple[int, list[int]]:
    """The declared ``n_nearest`` and ``hidden`` widths, each within the checkpoint bounds,
    checked before anything is allocated from them."""
    n_nearest = checkpoint.declared_int(ckpt, "n_nearest", 1, checkpoint.MAX_N_NEAREST, src)
    hidden = ckpt.get("hidden")
    if (
        not isinstance(hidden, list | tuple)
        or not 1 <= len(hidden) <= checkpoint.MAX_LAYERS
        or not all(checkpoint.is_int(h) and 1 <= h <= checkpoint.MAX_HIDDEN_WIDTH for h in hidden)
    ):
        raise src.bad(
            "hidden",
            hidden,
            f"a list of 1 to {checkpoint.MAX_LAYERS} layer widths, each an integer from 1 to "
            f"{checkpoint.MAX_HIDDEN_WIDTH}",
        )
    return n_nearest, [int(h) for h in hidden]


def _check_observation(ckpt: dict, n_nearest: int, n_obs: int, src: checkpoint.Source) -> None:
    """Refuse a network trained on another observation layout than this uavxai's.

    The stored probe is the observation of a fixed encounter at training time; if today's
    :func:`observe` maps it elsewhere, the network's inputs would silently mean other things.
    """
    probe = ckpt.get("obs_probe")
    if (
        ckpt.get("obs_dim") != n_obs
        or not isinstance(probe, torch.Tensor)
        or tuple(probe.shape) != (n_obs,)
        or not probe.is_floating_point()
        or not np.allclose(probe.numpy(), _probe_observation(n_nearest), atol=1e-5)
    ):
        raise src.error(
            f"trained on an observation that differs from this uavxai's (size "
            f"{short_repr(ckpt.get('obs_dim'))}, {n_nearest} nearest intruders); retrain it."
        )


# ------------------------------------------------------------------------------------ planners
class LearnedPlanner:
    """A greedy policy over trained Q-networks, in the planner API (README, planner API).

    Deterministic: the same inputs give the same decision, whatever the seed.
    """

    algo = "dqn"
    label = "DQN"

    def __init__(
        self,
        config: PlannerConfig | None = None,
        checkpoint: str | Path | None = None,
        *,
        name: str | None = None,
    ) -> None:
        self.config = (config or PlannerConfig()).whole_goal()
        self.name = name or self.algo
        self.nets, self.info = load_checkpoint(checkpoint, self.algo)
        self.n_nearest = int(self.info["n_nearest"])
        self.model = EncounterModel(self.config)

    def reset(self, seed: int) -> None:
        """Nothing to re-seed: the policy is greedy."""

    @torch.no_grad()
    def q_values(self, obs: np.ndarray) -> dict[str, np.ndarray]:
        """Each network's Q-values (9,) for one observation."""
        x = torch.as_tensor(obs, dtype=torch.float32)[None]
        return {k: net(x)[0].numpy().astype(float) for k, net in self.nets.items()}

    def choose(self, q: dict[str, np.ndarray]) -> tuple[int, np.ndarray]:
        """(action, the Q reported per action)."""
        return int(np.argmax(q["q"])), q["q"]

    def plan(
        self, own: Ownship, intruders: Sequence[Intruder], goal: Goal, *, step: int = 0
    ) -> Decision:
        t0 = time.perf_counter()
        check_plan_inputs(own, intruders, goal)  # as the tree planners do
        cfg, model = self.config, self.model
        root = ownship_state(own)
        pos, vel = intruder_arrays(intruders)
        goal_xyz = np.asarray(goal, dtype=float)
        q = self.q_values(observe(root, pos, vel, goal_xyz, cfg, self.n_nearest))
        action, q_report = self.choose(q)

        # What the encounter model says each action leads to, held for one tree level's time.
        hold = cfg.action_hold_s
        track = model.predict(pos, vel, hold)
        seg = model.fly(
            np.repeat(root[None], N_ACTIONS, axis=0),
            np.arange(N_ACTIONS),
            goal_xyz,
            hold,
            track,
            cull=False,
            exact=True,
        )
        ids = [i.id for i in intruders]
        children = []
        for a in range(N_ACTIONS):
            finite = bool(np.isfinite(seg.min_sep[a]))
            children.append(
                ChildStats(
                    action=a,
                    bank_cmd_rad=float(bank_command(root[PHI_CMD], a, cfg)),
                    accel_mps2=float(accel_command(a, cfg)),
                    visits=0,
                    q=float(q_report[a]),
                    predicted_min_separation_m=float(seg.min_sep[a]),
                    closest_intruder=ids[int(seg.closest[a])] if finite else None,
                    time_to_closest_s=float(seg.t_closest[a]) if finite else None,
                    outcome=_OUTCOME.get(int(seg.event[a]), ""),
                    effect=flies(a, own, cfg),
                )
            )
            # the numbers the words quote: a collision's predicted miss, not where it began
            line = measure_line(
                [seg.samples[a]], [0], [(int(seg.event[a]), float(seg.t_event[a]))], [track],
                hold, cfg.d_min_m,
            )  # fmt: skip
            children[-1] = with_measure(children[-1], line, ids)
        period = cfg.decision_period_s
        next_seg = model.fly(
            root[None], np.array([action]), goal_xyz, period, model.predict(pos, vel, period),
            cull=False, exact=True,
        )  # fmt: skip
        sentence, counterfactual = self.explain(action, q, children)
        return Decision(
            bank_cmd_rad=float(bank_command(own.bank, action, cfg)),
            accel_mps2=float(accel_command(action, cfg)),
            action=action,
            children=children,
            words=(sentence, counterfactual),
            plan=np.concatenate([root[None, :3], seg.samples[action, 1:]]),
            predicted_min_separation_m=float(next_seg.min_sep[0]),
            branch_min_separation_m=children[action].predicted_min_separation_m,
            branch_horizon_s=hold,
            ms=1000.0 * (time.perf_counter() - t0),
            planner=self.name,
            d_min_m=cfg.d_min_m,
        )

    def explain(
        self, action: int, q: dict[str, np.ndarray], children: list[ChildStats]
    ) -> tuple[str, str]:
        qa = q["q"]
        sentence = (
            f"{self.label}: Q({action_name(action)}) = {qa[action]:.2f} highest"
            f"{_flown(children[action])}; {_keeps(children[action], self.config)}"
        )
        others = _other_manoeuvres(children, action)
        if not others:
            return sentence, ""
        runner = max(others, key=lambda a: qa[a])
        why_not = (
            f"why not {action_name(runner)}{_flown(children[runner])}: Q {qa[runner]:.2f} "
            f"against {qa[action]:.2f}; {_keeps(children[runner], self.config)}"
        )
        return sentence, why_not


class DQNPlanner(LearnedPlanner):
    algo = "dqn"
    label = "DQN"


class SafeDQNPlanner(LearnedPlanner):
    algo = "safe_dqn"
    label = "Safe-DQN"

    def choose(self, q: dict[str, np.ndarray]) -> tuple[int, np.ndarray]:
        a = int(safe_action(torch.as_tensor(q["goal"]), torch.as_tensor(q["safety"])))
        return a, q["goal"] + q["safety"]

    def explain(
        self, action: int, q: dict[str, np.ndarray], children: list[ChildStats]
    ) -> tuple[str, str]:
        qg, qs = q["goal"], q["safety"]
        median = float(np.sort(qs)[(N_ACTIONS - 1) // 2])
        passed = qs >= median
        sentence = (
            f"{self.label}: {int(passed.sum())} of 9 actions pass the safety filter "
            f"(Q_safety >= median {median:.2f}); {action_name(action)} has the best "
            f"Q_goal + Q_safety = {qg[action] + qs[action]:.2f} (goal {qg[action]:.2f}, "
            f"safety {qs[action]:.2f}) among them{_flown(children[action])}; "
            f"{_keeps(children[action], self.config)}"
        )
        others = _other_manoeuvres(children, action)
        filtered = [a for a in others if qg[a] > qg[action] and not passed[a]]
        safe = [a for a in others if passed[a]]
        if filtered:  # the goal would have preferred it: the filter is why not
            greedy = max(filtered, key=lambda a: qg[a])
            why_not = (
                f"why not {action_name(greedy)}{_flown(children[greedy])} (better for the "
                f"goal, Q_goal {qg[greedy]:.2f}): its Q_safety {qs[greedy]:.2f} is below the "
                f"median; {_keeps(children[greedy], self.config)}"
            )
        elif not safe:
            return sentence, ""
        else:
            runner = max(safe, key=lambda a: qg[a] + qs[a])
            why_not = (
                f"why not {action_name(runner)}{_flown(children[runner])}: Q_goal + Q_safety "
                f"{qg[runner] + qs[runner]:.2f} against {qg[action] + qs[action]:.2f}; "
                f"{_keeps(children[runner], self.config)}"
            )
        return sentence, why_not


_OUTCOME = {1: "goal", 2: "collision", 3: "out_of_bounds"}


def _flown(c: ChildStats) -> str:
    """" (flown as bank left, hold speed: clamped at a limit)" when the action's commands are
    clamped into another manoeuvre; "" when it flies as itself."""
    return "" if c.effect is None else f" (flown as {action_name(c.flies)}: clamped at a limit)"


def _other_manoeuvres(children: list[ChildStats], action: int) -> list[int]:
    """The actions that fly a manoeuvre other than ``action``'s: the only real alternatives."""
    flown = children[action].flies
    return [c.action for c in children if c.flies != flown]


def _keeps(c: ChildStats, cfg: PlannerConfig) -> str:
    """What the encounter model predicts for an action held ``action_hold_s``, in words."""
    hold = f"held {cfg.action_hold_s:g} s"
    if c.meets is not None:
        m = c.meets
        return (
            f"{hold} it meets intruder {_id(m.intruder)} in {m.time_s:.1f} s (predicted miss "
            f"{m.miss_m:.0f} m, {m.needed_m:.0f} m needed)"
        )
    if c.closest_intruder is None or not math.isfinite(c.predicted_min_separation_m):
        return f"{hold} it meets no intruder"
    return (
        f"{hold} it is predicted to keep {c.predicted_min_separation_m:.0f} m from intruder "
        f"{_id(c.closest_intruder)} (in {c.time_to_closest_s or 0.0:.0f} s)"
    )


def _id(intruder_id: object) -> str:
    """"7" for intruder 7 or "intruder-7": the sentence already says "intruder"."""
    return str(intruder_id).removeprefix("intruder-")


def make_learned_planner(
    algo: str, config: PlannerConfig | None = None, checkpoint: str | Path | None = None
) -> LearnedPlanner:
    """The planner for ``algo`` ('dqn' or 'safe_dqn') with ``checkpoint`` (None: shipped)."""
    if algo == "dqn":
        return DQNPlanner(config, checkpoint)
    if algo == "safe_dqn":
        return SafeDQNPlanner(config, checkpoint)
    raise CheckpointError(f"unknown learned avoidance algorithm '{algo}'; known: {ALGOS}")
