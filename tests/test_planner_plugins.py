"""Planners other packages install (issue 29: a registry user code can extend): an entry point
in the group `uavxai.planners` names a factory, and a scenario, `--methods` and a campaign may
then name its planner. Each test installs a real distribution's metadata (a *.dist-info folder
with entry_points.txt) on sys.path, which importlib.metadata reads as it reads pip's."""

from __future__ import annotations

from pathlib import Path

import pytest

from uavxai.avoidance.planners import make_planner
from uavxai.avoidance.types import PlannerConfig
from uavxai.errors import ScenarioError, UserError
from uavxai.scenario import default_scenario, load_scenario
from uavxai.vocabulary import avoidance_planners, plugin_planners

MODULE = '''
from uavxai.avoidance.direct import DirectPlanner


def straight(config, checkpoint):
    return DirectPlanner(config, name="straight_plugin")


def not_a_planner(config, checkpoint):
    return object()
'''


def _install(root: Path, entries: dict[str, str], module: str = MODULE, dist: str = "demo") -> None:
    """A package `uavxai_plugin_<dist>` and its metadata, as pip would leave them."""
    (root / f"uavxai_plugin_{dist}.py").write_text(module, encoding="utf-8")
    info = root / f"uavxai_plugin_{dist}-0.1.dist-info"
    info.mkdir()
    (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: uavxai-plugin-{dist}\n"
                                   "Version: 0.1\n", encoding="utf-8")  # fmt: skip
    lines = "".join(f"{name} = uavxai_plugin_{dist}:{obj}\n" for name, obj in entries.items())
    (info / "entry_points.txt").write_text(f"[uavxai.planners]\n{lines}", encoding="utf-8")


@pytest.fixture
def plugins(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.syspath_prepend(str(tmp_path))
    plugin_planners.cache_clear()  # a process reads its plugins once: this one installs some
    yield tmp_path
    plugin_planners.cache_clear()


def test_an_installed_plugin_is_a_planner_a_scenario_and_a_campaign_may_name(plugins) -> None:
    from uavxai.campaign import run_campaign_episode

    _install(plugins, {"straight_plugin": "straight"})
    assert plugin_planners() == ("straight_plugin",)
    assert avoidance_planners()[-1] == "straight_plugin"
    planner = make_planner("straight_plugin", PlannerConfig())
    assert planner.name == "straight_plugin"
    sc = default_scenario()
    sc = sc.model_validate({**sc.model_dump(), "avoidance": {
        **sc.avoidance.model_dump(), "planner": "straight_plugin"}})  # fmt: skip
    assert sc.avoidance.planner == "straight_plugin"
    row = run_campaign_episode(sc, "straight_plugin", 2, 0)
    assert row["method"] == "straight_plugin" and row["steps"] > 0


def test_without_the_plugin_the_scenario_names_what_is_allowed(tmp_path: Path) -> None:
    path = tmp_path / "s.yaml"
    path.write_text("avoidance:\n  planner: straight_plugin\n", encoding="utf-8")
    with pytest.raises(ScenarioError, match="straight_plugin.*is not one of mcts"):
        load_scenario(path)


def test_a_plugin_cannot_take_a_built_in_name_or_an_unsafe_one(plugins) -> None:
    _install(plugins, {"mcts": "straight", "Bad-Name": "straight", "ok_one": "straight"})
    assert plugin_planners() == ("ok_one",)
    assert make_planner("mcts", PlannerConfig()).name == "mcts"  # the built-in kept it


def test_a_broken_plugin_is_named_not_a_traceback(plugins) -> None:
    _install(plugins, {"broken": "straight"}, module="raise RuntimeError('boom')\n", dist="b")
    _install(plugins, {"fake": "not_a_planner"}, dist="c")
    with pytest.raises(UserError, match=r"'broken' \(entry point uavxai_plugin_b:straight.*boom"):
        make_planner("broken", PlannerConfig())
    with pytest.raises(UserError, match="'fake' .*returned a 'object' object, not a planner"):
        make_planner("fake", PlannerConfig())


def test_a_plugin_flies_the_paper_set_only(plugins) -> None:
    _install(plugins, {"straight_plugin": "straight"})
    with pytest.raises(UserError, match="avoidance.actions: vertical"):
        make_planner("straight_plugin", PlannerConfig(actions="vertical"))
