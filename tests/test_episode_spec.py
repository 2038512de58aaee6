"""One episode spec (issue 29): `uavxai run`, `uavxai evaluate` (kinematic and JSBSim), the
kinematic runner and the training env fly the same episode for a scenario and seed, because
all of them build it with :func:`uavxai.sim.spec.episode_spec`."""

from __future__ import annotations

import numpy as np
import pytest

from uavxai.campaign import campaign_spec
from uavxai.learning.env import EncounterEnv
from uavxai.scenario import default_scenario
from uavxai.service.stage import plan_service
from uavxai.sim.build import open_world, run_kinematic
from uavxai.sim.run import run_spec
from uavxai.sim.spec import EpisodeSpec, episode_goal, episode_spec

SEED = 7
# No ownship.goal (the goal is the service point) and no time on station (`uavxai run` flies
# a transit, as evaluate does); three intruders drawn from the seed; the truth picture, so
# that what the planner saw first is where the intruders were.
SCENARIO = default_scenario(
    "spec", seed=SEED, mission={"service_s": 0}, intruders={"count": 3},
    avoidance={"max_steps": 40}, surveillance={"model": "truth"},
)  # fmt: skip


def _episode(s: EpisodeSpec) -> tuple:
    """What makes two episodes the same encounter: seed, start, goal, intruders, budget."""
    return s.seed, s.start, s.goal, s.intruders, s.max_steps, s.mission is None


def _specs(sc) -> dict[str, EpisodeSpec]:
    """The spec each entry point flies for ``sc`` at its own seed."""
    n = sc.intruders.n  # `uavxai evaluate --intruders N` with the scenario's count
    env = EncounterEnv(sc, n_intruders=n)
    env.reset(seed=sc.seed)
    return {
        "run": run_spec(sc, plan_service(sc)),
        "evaluate-kinematic": campaign_spec(sc, n, sc.seed, "kinematic"),
        "evaluate-jsbsim": campaign_spec(sc, n, sc.seed, "jsbsim"),
        "env": env.episode_spec,
    }


@pytest.mark.parametrize("named_goal", [False, True], ids=["service-point", "ownship-goal"])
def test_run_evaluate_and_env_build_the_same_episode(named_goal):
    sc = SCENARIO
    if named_goal:
        sc = default_scenario("spec", seed=SEED, intruders={"count": 3},
                              ownship={"goal": [1500, 400, 130]})  # fmt: skip
    specs = _specs(sc)
    first = specs["run"]
    for name, spec in specs.items():
        assert _episode(spec) == _episode(first), name
    assert first.goal == episode_goal(sc)
    expected = (1500.0, 400.0, 130.0) if named_goal else tuple(plan_service(sc).service_point)
    assert first.goal == pytest.approx(expected)
    assert len(first.intruders) == 3 and first.max_steps == sc.avoidance.max_steps
    assert (specs["run"].dynamics, specs["evaluate-jsbsim"].dynamics) == ("jsbsim", "jsbsim")
    assert (specs["evaluate-kinematic"].dynamics, specs["env"].dynamics) == ("kinematic",) * 2


def test_the_worlds_first_states_are_the_same():
    specs = _specs(SCENARIO)
    with open_world(specs["evaluate-kinematic"]) as world:
        kin = world.state()
    # the env's live episode
    env = EncounterEnv(SCENARIO, n_intruders=SCENARIO.intruders.n)
    env.reset(seed=SEED)
    pos, vel = env.intruder_arrays()
    np.testing.assert_array_equal(pos, kin.pos[1:])
    np.testing.assert_array_equal(vel, kin.vel[1:])
    own = env.ownship
    assert (own.x, own.y, own.h) == tuple(kin.pos[0])
    np.testing.assert_array_equal(env.goal, specs["evaluate-kinematic"].goal)
    # the kinematic runner: what its planner saw at the first decision
    r = run_kinematic("none", SCENARIO, SEED, keep_decisions=True)
    seen = r.records[0]["state"]
    assert [seen["ownship"][k] for k in "xyh"] == pytest.approx(kin.pos[0].tolist(), abs=1e-9)
    by_id = sorted(seen["intruders"], key=lambda i: i["id"])
    flown = [[i[k] for k in "xyh"] for i in by_id]
    np.testing.assert_allclose(flown, kin.pos[1:], atol=1e-9)
    assert r.steps <= SCENARIO.avoidance.max_steps
    # JSBSim: `uavxai run` and `uavxai evaluate --dynamics jsbsim` start the same world
    with open_world(specs["run"]) as a, open_world(specs["evaluate-jsbsim"]) as b:
        sa, sb = a.state(), b.state()
    np.testing.assert_array_equal(sa.pos, sb.pos)
    np.testing.assert_array_equal(sa.vel, sb.vel)
    np.testing.assert_allclose(sa.pos[:, :2], kin.pos[:, :2], atol=1e-6)  # same placement


def test_same_seed_same_spec_another_seed_another_draw():
    a, b = episode_spec(SCENARIO, SEED), episode_spec(SCENARIO, SEED)
    assert a == b
    c = episode_spec(SCENARIO, SEED + 1)
    assert c.intruders != a.intruders and len(c.intruders) == len(a.intruders)
    assert c.goal == a.goal  # the goal is the scenario's (its own seed's), not the draw's
    assert episode_spec(SCENARIO, SEED, n_intruders=5).intruders[:3] == a.intruders


def test_a_mission_lengthens_the_step_budget_and_keeps_the_rest():
    sc = default_scenario("spec", seed=SEED, intruders={"count": 3})  # 300 s on station
    run, evaluate = run_spec(sc, plan_service(sc)), campaign_spec(sc, 3, SEED, "jsbsim")
    assert run.mission is not None and evaluate.mission is None
    assert run.max_steps > evaluate.max_steps == sc.avoidance.max_steps
    assert (run.start, run.goal, run.intruders) == (evaluate.start, evaluate.goal,
                                                    evaluate.intruders)  # fmt: skip


def test_reset_options_set_the_episode_and_refuse_unknown_keys():
    env = EncounterEnv(SCENARIO)
    start = SCENARIO.ownship.start.model_copy(update={"x": 300.0})
    env.reset(seed=1, options={"start": start, "goal": (900, 900, 120), "n_intruders": 2})
    spec = env.episode_spec
    assert spec.start == start and spec.goal == (900.0, 900.0, 120.0)
    assert spec.intruders == episode_spec(SCENARIO, 1, n_intruders=2, start=start).intruders
    assert env.ownship.x == 300.0
    with pytest.raises(ValueError, match="allowed: start, goal, intruders, n_intruders"):
        env.reset(seed=1, options={"speed": 3})


def test_unknown_dynamics_is_refused_by_name():
    from uavxai.errors import UserError

    with pytest.raises(UserError, match="dynamics 'xplane' is not one of jsbsim, kinematic"):
        episode_spec(SCENARIO, dynamics="xplane")
