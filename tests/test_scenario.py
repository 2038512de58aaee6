"""Scenario schema: defaults, ranges, and broken files that must exit 2 with a clear message."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import pytest

from uavxai.avoidance.types import PlannerConfig
from uavxai.cli import main
from uavxai.errors import ScenarioError
from uavxai.paths import scenarios_dir
from uavxai.scenario import default_scenario, load_scenario

REPO = Path(__file__).resolve().parents[1]


def test_defaults_match_spec() -> None:
    sc = default_scenario()
    assert sc.seed == 0
    assert sc.world.x == (0, 2000) and sc.world.h == (50, 300)
    assert sc.comms.users.k == 10 and sc.comms.power_levels == 6 and sc.comms.p_max_w == 1.0
    assert sc.comms.environment == "urban" and sc.comms.access == "shared"
    assert sc.service.planner == "d3qn" and sc.service.steps == 100
    assert sc.intruders.count == 20 and sc.intruders.speed_mps == (15, 30)
    assert sc.avoidance.planner == "mcts" and sc.avoidance.d_min_m == 50
    assert sc.avoidance.mcts.simulations == 200 and sc.avoidance.mcts.depth == 4
    assert sc.bridge.system_id == 1 and sc.log.rerun is True


def test_every_shipped_scenario_validates() -> None:
    files = sorted(scenarios_dir().glob("*.yaml"))
    assert any(f.name == "demo.yaml" for f in files)
    for f in files:
        assert load_scenario(f).name


def test_the_stress_scenarios_of_the_results_differ_from_manoeuvring_only_as_they_say() -> None:
    """docs/results/manoeuvring/stress/*.yaml: each is scenarios/manoeuvring.yaml with the one
    change its comment names (and its own name)."""
    base = load_scenario(scenarios_dir() / "manoeuvring.yaml").model_dump()
    folder = Path(__file__).parent.parent / "docs" / "results" / "manoeuvring" / "stress"
    poor = {("surveillance", k) for k in ("nacp", "nacv", "latency_s", "dropout")}
    changed = {
        "noncooperative": {("surveillance", "noncooperative")},
        "poor-adsb": poor,
        "co-altitude": {("intruders", "altitude_m")},
        "goal-seeking": {("intruders", "behaviour")},
        "poor-adsb-horizon8": poor | {("avoidance", "mcts")},
        "horizon8": {("avoidance", "mcts")},
    }
    for stem, keys in changed.items():
        sc = load_scenario(folder / f"{stem}.yaml").model_dump()
        assert sc["name"] == f"stress-{stem}"
        diff = {(s, k) for s in base if isinstance(base[s], dict)
                for k in base[s] if base[s][k] != sc[s][k]}  # fmt: skip
        assert diff == keys, stem


def test_demo_is_the_defaults_with_walking_users_and_ofdma() -> None:
    demo = load_scenario(scenarios_dir() / "demo.yaml")
    assert demo == default_scenario(
        "demo",
        comms={"access": "ofdma", "users": {"mobility": {"model": "random_waypoint"}}},
        service={"replan_s": 60},
    )


# (file content, words the message must contain)
BROKEN: list[tuple[str, tuple[str, ...]]] = [
    ("name: x\nworld: {x: [0, 100], hh: 3}\n", ("world.hh", "Did you mean 'h'")),
    ("name: x\ncoms: {}\n", ("coms", "Did you mean 'comms'")),
    ("name: x\ncomms: {power_levels: 1}\n", ("comms.power_levels", "greater than or equal to 2")),
    ("name: x\ncomms: {p_max_w: 0}\n", ("comms.p_max_w", "greater than 0")),
    ("name: x\ncomms: {p_max_w: 1 W}\n", ("comms.p_max_w", "number")),
    ("name: x\ncomms: {environment: rural}\n", ("comms.environment", "urban")),
    ("name: x\ncomms: {access: tdma}\n", ("comms.access", "ofdma")),
    ("name: x\nworld: {h: [300, 50]}\n", ("world.h", "min < max")),
    ("name: x\nworld: {h: [-10, 50]}\n", ("world.h", "above the ground")),
    ("name: x\nworld: {x: [0]}\n", ("world.x",)),
    ("seed: 3\n", ("name", "required")),
    ("name: x\nseed: -1\n", ("seed", "greater than or equal to 0")),
    ("name: x\navoidance: {planner: astar}\n", ("avoidance.planner", "mcts")),
    ("name: x\navoidance: {mcts: {depth: 0}}\n", ("avoidance.mcts.depth",)),
    ("name: x\navoidance: {mcts: {reach_horizon_s: -2}}\n", ("mcts.reach_horizon_s", "0")),
    ("name: x\navoidance: {mcts: {own_error_10s_m: -1}}\n", ("mcts.own_error_10s_m", "0")),
    ("name: x\navoidance: {mcts: {own_error_10s_m: lots}}\n", ("mcts.own_error_10s_m",)),
    ("name: x\navoidance: {bank_step_deg: 40}\n", ("bank_step_deg", "bank_limit_deg")),
    ("name: x\nownship: {start: {x: 5000}}\n", ("ownship.start", "outside the world")),
    ("name: x\nownship: {aircraft: cessna}\n", ("aircraft 'cessna'", "known")),
    ("name: x\nbridge: {signing_key_hex: abc}\n", ("signing_key_hex", "64 hexadecimal")),
    ("name: x\nbridge: {mavlink: 'http://x'}\n", ("bridge.mavlink", "udpout:HOST:PORT")),
    ("name: x\ncomms: {users: {count: 3, positions: [[1, 2]]}}\n", ("comms.users", "count is 3")),
    ("name: x\ncomms: {users: {region: {x: [0, 5000]}}}\n", ("region", "inside the world")),
    ("name: x\nintruders: {list: [{x: 1, y: 2}]}\n", ("intruders.list.0.h", "required")),
    ("name: x\nbridge: {ground_stations: [[255, 127.0.0.1]]}\n",
     ("bridge.ground_stations.0", "a section belongs here", "system_id, address")),
    ("name: x\nbridge: [1, 2]\n", ("'bridge'", "a section belongs here", "mavlink")),
    ("name: x\nworld: [1, 2\n", ("not valid YAML", "line")),
    ("- just\n- a list\n", ("YAML mapping",)),
    ("", ("YAML mapping", "empty")),
    ("name: x\nworld: {x: [0, .inf]}\n", ("world.x",)),
]


@pytest.mark.parametrize(("text", "words"), BROKEN, ids=[str(i) for i in range(len(BROKEN))])
def test_broken_scenario_message(tmp_path: Path, text: str, words: tuple[str, ...]) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    with pytest.raises(ScenarioError) as info:
        load_scenario(path)
    msg = str(info.value)
    assert str(path) in msg
    for w in words:
        assert w in msg, f"{w!r} not in message:\n{msg}"


@pytest.mark.parametrize(("text", "words"), BROKEN[:6] + BROKEN[-4:])
def test_validate_exits_2_without_traceback(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str, words: tuple[str, ...]
) -> None:
    path = tmp_path / "broken.yaml"
    path.write_text(text)
    assert main(["validate", str(path)]) == 2
    err = capsys.readouterr().err
    assert "Traceback" not in err and str(path) in err


def test_missing_and_binary_files(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(tmp_path / "nope.yaml")]) == 2
    assert "no such scenario file" in capsys.readouterr().err
    binary = tmp_path / "bin.yaml"
    binary.write_bytes(b"\xff\xfe\x00garbage")
    assert main(["validate", str(binary)]) == 2
    assert "cannot read" in capsys.readouterr().err or "YAML" in capsys.readouterr().err


def test_validate_ok(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["validate", str(REPO / "scenarios" / "demo.yaml")]) == 0
    assert "valid scenario 'demo'" in capsys.readouterr().out


def test_bad_flags_exit_2(capsys: pytest.CaptureFixture[str]) -> None:
    demo = str(REPO / "scenarios" / "demo.yaml")
    for argv in (
        ["run", demo, "--seed", "abc"],
        ["run", demo, "--mavlink", "serial0"],
        ["run", demo, "--realtime", "-1"],
        ["evaluate", demo, "--methods", "mcts,astar", "--intruders", "5"],
        ["evaluate", demo, "--methods", "mcts", "--intruders", "five"],
        ["train", demo, "--stage", "avoidance", "--algo", "d3qn"],
        ["frobnicate"],
    ):
        assert main(argv) == 2, argv
        err = capsys.readouterr().err
        assert "error" in err and "Traceback" not in err


def test_existing_output_is_not_overwritten(tmp_path: Path, capsys) -> None:
    out = tmp_path / "out"
    out.mkdir()
    (out / "keep.txt").write_text("precious")
    demo = str(REPO / "scenarios" / "demo.yaml")
    assert main(["service", demo, "--out", str(out)]) == 2
    assert "--force" in capsys.readouterr().err
    assert (out / "keep.txt").read_text() == "precious"


def test_console_script_runs() -> None:
    """The installed `uavxai` entry point exists and exits 2 on a bad file."""
    proc = subprocess.run(
        [sys.executable, "-m", "uavxai", "validate", "/nonexistent.yaml"],
        capture_output=True,
        text=True,
    )
    assert proc.returncode == 2 and "Traceback" not in proc.stderr


# ------------------------------------------------------------------ reference and new sections
def _sub_model(ann: object, listed: bool = False) -> tuple[type | None, bool]:
    """The pydantic model inside an annotation (``X | None``, ``list[X]``, ``Annotated``),
    and whether it sits inside a list."""
    import typing

    from pydantic import BaseModel

    if isinstance(ann, type) and issubclass(ann, BaseModel):
        return ann, listed
    inner = listed or typing.get_origin(ann) is list
    for arg in typing.get_args(ann):
        found = _sub_model(arg, inner)
        if found[0] is not None:
            return found
    return None, False


def _schema_keys(model: type, prefix: str = "") -> list[str]:
    """Every dotted key of the schema, sections included, descending into sub-models and
    lists of models (``intruders.list[].x``)."""
    keys = []
    for name, field in model.model_fields.items():
        keys.append(prefix + name)
        sub, listed = _sub_model(field.annotation)
        if sub is not None:
            keys += _schema_keys(sub, prefix + name + ("[]." if listed else "."))
    return keys


def test_reference_documents_every_schema_key() -> None:
    from uavxai.scenario import Scenario

    doc = (REPO / "docs" / "scenario.md").read_text(encoding="utf-8")
    keys = _schema_keys(Scenario)
    assert "intruders.list[].speed_mps" in keys and "surveillance.sensor.sigma_m" in keys
    sections = {k.rsplit(".", 1)[0].removesuffix("[]") for k in keys if "." in k}
    leaves = [k for k in keys if k not in sections]
    assert len(leaves) > 90
    missing = [k for k in leaves if f"`{k}`" not in doc]
    assert not missing, f"not in docs/scenario.md: {missing}"


CONTRACT_KEYS = [  # the sections and keys added to the first version's scenario
    "environment.wind.speed_mps", "environment.wind.from_deg", "environment.turbulence",
    "surveillance.model", "surveillance.rate_hz", "surveillance.nacp", "surveillance.nacv",
    "surveillance.latency_s", "surveillance.dropout", "surveillance.noncooperative",
    "surveillance.sensor.range_m", "surveillance.sensor.fov_deg", "surveillance.sensor.sigma_m",
    "mission.service_s", "mission.return_home", "comms.users.mobility.model",
    "comms.users.mobility.speed_mps", "comms.users.mobility.pause_s", "service.platform",
    "service.replan_s", "avoidance.actions", "intruders.flow",
]


def test_contract_sections_are_in_the_schema_and_the_reference() -> None:
    from uavxai.scenario import Scenario

    keys = set(_schema_keys(Scenario))
    doc = (REPO / "docs" / "scenario.md").read_text(encoding="utf-8")
    for key in CONTRACT_KEYS:
        assert key in keys, key
        assert f"`{key}`" in doc, key


def test_section_configs_take_the_schemas_defaults_and_values() -> None:
    """The plain configs of the surveillance, environment and walking users are the schema's
    section field for field, their defaults the schema's (declared there once): a scenario
    that omits a section and the config built without arguments agree, and every value set
    in the scenario reaches the config. (The mission's are read from the schema only.)"""
    from uavxai.comms.mobility import UserMobility
    from uavxai.dynamics.environment import EnvironmentConfig
    from uavxai.surveillance.adsb import SurveillanceConfig
    from uavxai.surveillance.sensor import SensorConfig

    sc = default_scenario()
    assert SurveillanceConfig.from_scenario(sc) == SurveillanceConfig()
    assert EnvironmentConfig.from_scenario(sc) == EnvironmentConfig()
    walk, plain = UserMobility.from_scenario(sc), UserMobility([[0.0, 0.0]], ((0, 1), (0, 1)))
    assert (walk.model, walk.speed_mps, walk.pause_s) == (
        plain.model, plain.speed_mps, plain.pause_s)  # fmt: skip
    odd = default_scenario(
        surveillance={"model": "truth", "rate_hz": 2, "nacp": 9, "nacv": 1, "latency_s": 0.2,
                      "dropout": 0.1, "noncooperative": 0.25, "preroll_s": 3,
                      "sensor": {"range_m": 800, "fov_deg": 120, "sigma_m": 5}},
        environment={"wind": {"speed_mps": 4, "from_deg": 90}, "turbulence": "light"},
        comms={"users": {"mobility": {"model": "random_waypoint", "speed_mps": [1, 2],
                                      "pause_s": 10}}},
    )  # fmt: skip
    assert SurveillanceConfig.from_scenario(odd) == SurveillanceConfig(
        "truth", 2.0, 9, 1, 0.2, 0.1, 0.25, SensorConfig(800.0, 120.0, 5.0), 3.0)  # fmt: skip
    assert EnvironmentConfig.from_scenario(odd) == EnvironmentConfig(4.0, 90.0, "light")
    walk = UserMobility.from_scenario(odd)
    assert (walk.model, walk.speed_mps, walk.pause_s) == ("random_waypoint", (1, 2), (10, 10))
    no_sensor = default_scenario(surveillance={"sensor": None})
    assert SurveillanceConfig.from_scenario(no_sensor).sensor is None
    assert sc.surveillance.model == "adsb" and sc.intruders.flow == "replace"
    assert sc.mission.service_s == 300 and sc.mission.return_home is True
    assert sc.environment.wind.from_deg == 270 and sc.environment.turbulence == "none"


def test_scenarios_using_the_new_sections_validate(tmp_path: Path) -> None:
    text = """
name: windy
environment: {wind: {speed_mps: 8, from_deg: 200}, turbulence: moderate}
surveillance: {model: truth, rate_hz: 2, nacp: 9, nacv: 1, latency_s: 0.2, dropout: 0.1,
               noncooperative: 0.25, sensor: {range_m: 800, fov_deg: 120, sigma_m: 5}}
mission: {service_s: 0, return_home: false}
comms: {users: {mobility: {model: random_waypoint, speed_mps: [1, 2], pause_s: 10}}}
service: {platform: hover, replan_s: 60}
avoidance: {actions: paper}
intruders: {flow: none}
"""
    path = tmp_path / "windy.yaml"
    path.write_text(text)
    sc = load_scenario(path)
    assert sc.environment.wind.speed_mps == 8 and sc.surveillance.sensor.fov_deg == 120
    assert sc.comms.users.mobility.speed_mps == (1, 2) and sc.intruders.flow == "none"
    path.write_text("name: x\nsurveillance: {sensor: null}\n")
    assert load_scenario(path).surveillance.sensor is None


# --------------------------------------------------------------- validate catches what run refuses
RUN_REFUSES: list[tuple[str, tuple[str, ...]]] = [
    ("service: {checkpoint: /nonexistent/model.pt}", ("service.checkpoint", "no such file")),
    ("avoidance: {planner: dqn, checkpoint: nope.pt}", ("avoidance.checkpoint", "no such file")),
    ("comms: {users: {positions: [[1000, 1000], [100, 100]]}}",
     ("positions[1]", "outside comms.users.region")),
    ("dynamics: {rate_hz: 30, trajectory_hz: 120}", ("rate_hz", "whole multiple")),
    ("dynamics: {rate_hz: 100, trajectory_hz: 30}", ("rate_hz", "whole multiple")),
    ("avoidance: {decision_period_s: 1.0e-9}", ("decision_period_s", "whole number")),
    ("avoidance: {decision_period_s: 1.05}", ("decision_period_s", "whole number")),
    ("avoidance: {decision_period_s: 0.25}", ("decision_period_s", "trajectory samples")),
    ("bridge: {command_timeout_s: 0.5}", ("command_timeout_s", "longer than")),
    ("world: {origin: {lat_deg: 90}}", ("world.origin.lat_deg", "85")),
    ("ownship: {start: {speed_mps: 8}}", ("ownship.start.speed_mps", "between 12 and 30")),
    ("ownship: {start: {speed_mps: 35}}", ("ownship.start.speed_mps", "between 12 and 30")),
    ("avoidance: {speed_mps: [40, 50]}", ("avoidance.speed_mps", "between 12 and 30")),
    ("intruders: {speed_mps: [20, 45]}", ("intruders.speed_mps", "between 12 and 30")),
    ("intruders: {list: [{x: 500, y: 500, h: 120, heading_deg: 0, speed_mps: 70}]}",
     ("intruders.list.0.speed_mps", "between 12 and 30")),
    ("intruders: {list: [{x: 500, y: 500, h: -100, heading_deg: 0, speed_mps: 20}]}",
     ("intruders.list.0", "world bounds", "h [50.0, 300.0]")),
    ("intruders: {list: [{x: 500, y: 500, h: 900, heading_deg: 0, speed_mps: 20}]}",
     ("intruders.list.0", "world bounds")),
    ("intruders: {altitude_m: [200, 400]}", ("intruders.altitude_m", "world.h")),
]


@pytest.mark.parametrize(("body", "words"), RUN_REFUSES, ids=[w[0] for _, w in RUN_REFUSES])
def test_validate_refuses_what_run_would(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], body: str, words: tuple[str, ...]
) -> None:
    path = tmp_path / "s.yaml"
    path.write_text(f"name: s\n{body}\n")
    for command in (["validate", str(path)], ["run", str(path), "--out", str(tmp_path / "o")]):
        assert main(command) == 2, command
        err = capsys.readouterr().err
        assert str(path) in err and "Traceback" not in err and "docs/scenario.md" in err
        for w in words:
            assert w in err, f"{w!r} not in:\n{err}"
    assert not (tmp_path / "o").exists()  # refused before anything was written


def test_flyable_speeds_are_the_ones_jsbsim_reads() -> None:
    """The schema reads the speed limits from the aircraft XML without JSBSim; JSBSim, loading
    the same aircraft, must report the same numbers."""
    from uavxai.dynamics.aircraft import Aircraft
    from uavxai.dynamics.geodesy import LocalFrame
    from uavxai.scenario import aircraft_speed_range

    sc = default_scenario()
    a = Aircraft("uav_fw", LocalFrame.from_origin(sc.world.origin), 1 / 120, seed=1)
    try:
        assert aircraft_speed_range("uav_fw") == pytest.approx(a.speed_range)
    finally:
        a.close()


def test_relative_checkpoints_resolve_against_the_scenario_folder(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    folder = tmp_path / "study"
    (folder / "models").mkdir(parents=True)
    (folder / "models" / "model.pt").write_bytes(b"not checked here")
    path = folder / "s.yaml"
    path.write_text(
        "name: s\nservice: {checkpoint: models/model.pt}\n"
        "avoidance: {planner: dqn, checkpoint: ./models/model.pt}\n"
    )
    elsewhere = tmp_path / "elsewhere"
    elsewhere.mkdir()
    monkeypatch.chdir(elsewhere)  # the working folder must not matter
    sc = load_scenario(path)
    expected = str((folder / "models" / "model.pt").resolve())
    assert Path(sc.service.checkpoint).resolve() == Path(expected)
    assert Path(sc.avoidance.checkpoint).is_absolute()
    assert Path(sc.avoidance.checkpoint).resolve() == Path(expected)


def test_shipped_scenarios_by_name(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch, capsys: pytest.CaptureFixture[str]
) -> None:
    monkeypatch.chdir(tmp_path)  # no scenarios/ folder here: the name must resolve to the package
    assert load_scenario("demo") == load_scenario(scenarios_dir() / "demo.yaml")
    assert load_scenario("head_on.yaml").name == "head_on"
    assert main(["validate", "demo"]) == 0
    assert "valid scenario 'demo'" in capsys.readouterr().out
    assert main(["validate", "nosuch"]) == 2
    err = capsys.readouterr().err
    assert "no such scenario file" in err
    for name in ("demo", "head_on", "dense", "crossing_swarm", "suburban"):
        assert name in err
    (tmp_path / "demo").mkdir()  # a folder of that name is not taken for the shipped file
    assert main(["validate", "demo"]) == 2


def test_the_vertical_action_set_validates_for_tree_planners_and_is_refused_by_the_others() -> None:
    for planner in ("mcts", "mcts_fast", "exhaustive", "none"):
        s = default_scenario("v", avoidance={"actions": "vertical", "planner": planner})
        assert PlannerConfig.from_scenario(s).n_actions == 11
    for planner in ("mvp", "dqn", "safe_dqn"):
        with pytest.raises(ScenarioError, match=rf"actions: vertical is flown by mcts.*{planner}"):
            default_scenario("v", avoidance={"actions": "vertical", "planner": planner})
    with pytest.raises(ScenarioError, match="paper.*vertical"):
        default_scenario("v", avoidance={"actions": "diagonal"})
