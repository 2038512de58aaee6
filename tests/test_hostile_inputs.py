"""Hostile scenario files: every one ends with exit 2 from `validate` and from `run`, a message
naming the file and the field (or the line), no traceback, bounded time and memory; and a seeded
schema fuzz in which every mutation gives a Scenario or a ScenarioError, nothing else."""

from __future__ import annotations

import copy
import math
import random
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest
import yaml

from uavxai.cli import main
from uavxai.errors import ScenarioError
from uavxai.paths import scenarios_dir
from uavxai.scenario import MAX_NODES, Scenario, load_scenario, parse_scenario

pytestmark = pytest.mark.usefixtures("release_cli_locks")


def laughs(depth: int) -> str:
    """The "billion laughs": each level a list of nine aliases of the level below."""
    lines = ["name: x", 'a0: &a0 ["lol","lol","lol","lol","lol","lol","lol","lol","lol"]']
    for i in range(1, depth):
        lines.append(f"a{i}: &a{i} [" + ",".join([f"*a{i - 1}"] * 9) + "]")
    return "\n".join(lines) + "\n"


def intruder(i: int) -> str:
    return f"{{x: {500 + i % 900}, y: 500, h: 120, heading_deg: 0, speed_mps: 20}}"


# (id, file content, words the message must contain)
CORPUS: list[tuple[str, str | bytes, tuple[str, ...]]] = [
    ("laughs-9", laughs(9), ("aliases", str(MAX_NODES))),
    ("laughs-10", laughs(10), ("aliases", str(MAX_NODES))),
    ("laughs-in-field", "name: x\nw: &w [1, 1]\n" + laughs(10).split("\n", 1)[1], ("aliases",)),
    ("duplicate-key", "name: x\nseed: 1\nseed: 2\n", ("duplicate key 'seed'", "line 3")),
    ("duplicate-nested", "name: x\nworld: {x: [0, 10], x: [0, 20]}\n", ("duplicate key 'x'",)),
    ("deep-flow", "name: x\nworld: " + "[" * 5000 + "]" * 5000 + "\n", ("nested deeper",)),
    ("deep-block", "name: x\n" + "".join(" " * i + f"k{i}:\n" for i in range(200)),
     ("nested deeper",)),
    ("seed-5000-digits", "name: x\nseed: " + "7" * 5000 + "\n", ("integer of 5000",)),
    ("seed-39-digits", "name: x\nseed: " + "9" * 39 + "\n", ("'seed'", "2147483647")),
    ("seed-float", "name: x\nseed: 1.5\n", ("'seed'",)),
    ("inf-bounds", "name: x\nworld: {x: [0, .inf]}\n", ("world.x",)),
    ("nan-start", "name: x\nownship: {start: {x: .nan}}\n", ("ownship.start.x",)),
    ("huge-start", "name: x\nownship: {start: {x: 1.0e+308}}\n", ("ownship.start.x",)),
    ("inf-speed", "name: x\nownship: {start: {speed_mps: .inf}}\n", ("ownship.start.speed_mps",)),
    ("huge-intruder-speed", "name: x\nintruders: {speed_mps: [15, 1.0e+308]}\n",
     ("intruders.speed_mps",)),
    ("huge-goal-radius", "name: x\navoidance: {goal_radius_m: 1e308}\n",
     ("avoidance.goal_radius_m", "less than or equal")),
    ("inf-d-min", "name: x\navoidance: {d_min_m: .inf}\n", ("avoidance.d_min_m",)),
    ("huge-min-start", "name: x\nintruders: {min_start_distance_m: 1.0e+300}\n",
     ("intruders.min_start_distance_m",)),
    ("no-positions", "name: x\ncomms: {users: {positions: []}}\n",
     ("comms.users.positions", "at least 1")),
    ("users-at-1e308", "name: x\ncomms: {users: {positions: [[1.0e+308, 1000]]}}\n",
     ("comms.users.positions",)),
    ("65-users", "name: x\ncomms: {users: {positions: [" + ",".join(["[1000, 1000]"] * 65)
     + "]}}\n", ("comms.users.positions", "at most 64")),
    ("40k-users", "name: x\ncomms: {users: {positions: [" + ",".join(["[1,1]"] * 40_000)
     + "]}}\n", ("more than", "values")),
    ("million-users", "name: x\ncomms: {users: {positions: [" + ",".join(["[1000,1000]"] * 10**6)
     + "]}}\n", ("too large", "256000")),
    ("500-listed-intruders-ok-size", "name: x\nintruders: {list: [" + ",".join(intruder(i) for i
     in range(500)) + "]}\nseed: -1\n", ("'seed'",)),
    ("501-listed-intruders", "name: x\nintruders: {list: [" + ",".join(intruder(i) for i in
     range(501)) + "]}\n", ("intruders.list", "at most 500")),
    ("intruder-below-ground", "name: x\nintruders: {list: [{x: 500, y: 500, h: -100, "
     "heading_deg: 0, speed_mps: 20}]}\n", ("intruders.list.0", "h [50.0, 300.0]")),
    ("intruder-above-world", "name: x\nintruders: {list: [{x: 500, y: 500, h: 5000, "
     "heading_deg: 0, speed_mps: 20}]}\n", ("intruders.list.0", "world bounds")),
    ("nul-raw", b"name: x\x00y\n", ("not valid YAML", "#x0000")),
    ("nul-escaped-name", 'name: "a\\0b"\n', ("'name'", "plain name")),
    ("ansi-name", 'name: "\\e[31mred\\e[0m"\n', ("'name'", "letters, digits")),
    ("dotdot-name", "name: '..'\n", ("'name'", "not '.' or '..'")),
    ("dot-name", "name: '.'\n", ("'name'",)),
    ("dotslash-name", "name: './'\n", ("'name'",)),
    ("absolute-name", "name: /home\n", ("'name'",)),
    ("space-name", "name: my run\n", ("'name'",)),
    ("traversal-aircraft", "name: x\nownship: {aircraft: ../../etc}\n", ("ownship.aircraft",)),
    ("decision-1e-9", "name: x\navoidance: {decision_period_s: 1.0e-9}\n",
     ("avoidance.decision_period_s", "whole number")),
    ("rates-30-120", "name: x\ndynamics: {rate_hz: 30, trajectory_hz: 120}\n",
     ("dynamics.rate_hz", "whole multiple")),
    ("timeout-short", "name: x\nbridge: {command_timeout_s: 0.5}\n",
     ("bridge.command_timeout_s", "decision_period_s")),
    ("lat-90", "name: x\nworld: {origin: {lat_deg: 90}}\n", ("world.origin.lat_deg",)),
    ("missing-checkpoint", "name: x\nservice: {checkpoint: /nonexistent/model.pt}\n",
     ("service.checkpoint", "no such file")),
    ("long-checkpoint", "name: x\nservice: {checkpoint: '" + "a" * 300 + "/m.pt'}\n",
     ("service.checkpoint",)),
    ("unknown-user-checkpoint", "name: x\navoidance: {checkpoint: '~nobody-here/m.pt'}\n",
     ("avoidance.checkpoint", "no such file")),
    ("python-tag", "name: !!python/object/apply:os.system ['true']\n", ("not valid YAML",)),
    ("undefined-alias", "name: x\nworld: *nowhere\n", ("not valid YAML", "alias")),
    ("recursive-anchor", "name: x\nworld: &w {x: *w}\n", ("not valid YAML",)),
    ("ansi-key", "name: x\n\"\\e[2Jboom\": 1\n", ("unknown key",)),
    ("huge-key", "name: x\n? " + "k" * 100_000 + "\n: 1\n", ("unknown key",)),
    ("long-plain-key", "name: x\n" + "k" * 100_000 + ": 1\n", ("not valid YAML",)),
    ("huge-string", "name: x\nbridge: {mavlink: '" + "u" * 200_000 + "'}\n", ("bridge.mavlink",)),
    ("list-not-mapping", "- a\n- b\n", ("YAML mapping",)),
    ("wind-too-strong", "name: x\nenvironment: {wind: {speed_mps: 1.0e+10}}\n",
     ("environment.wind.speed_mps",)),
    ("nacp-bad", "name: x\nsurveillance: {nacp: 12}\n", ("surveillance.nacp",)),
    ("dropout-1", "name: x\nsurveillance: {dropout: 1}\n", ("surveillance.dropout",)),
    ("mobility-walk-at-0", "name: x\ncomms: {users: {mobility: {model: random_waypoint, "
     "speed_mps: 0}}}\n", ("comms.users.mobility", "> 0")),
    ("binary", b"\xff\xfe\x00garbage", ("cannot read",)),
    # unflyable (issue 30): each field valid alone, the whole not
    ("wind-80-for-12-30-aircraft", "name: x\nenvironment: {wind: {speed_mps: 80}}\n",
     ("environment.wind.speed_mps = 80", "below 12 m/s")),
    ("orbit-9000-in-2-km", "name: x\nmission: {orbit_radius_m: 9000}\n",
     ("mission.orbit_radius_m = 9000", "at most 1000 m")),
    ("blind-planner", "name: x\nsurveillance: {noncooperative: 1.0, sensor: null}\n",
     ("surveillance.noncooperative", "surveillance.sensor null", "see no intruder")),
    # text is never converted to a number or a boolean, nor a number to a boolean
    ("quoted-seed", "name: x\nseed: '9'\n", ("'seed'", "text where a number")),
    ("quoted-bool", "name: x\nlog: {rerun: 'yes'}\n", ("'log.rerun'", "text where")),
    ("number-as-bool", "name: x\nlog: {rerun: 1}\n", ("'log.rerun'", "where true or false")),
    ("bool-as-number", "name: x\nseed: true\n", ("'seed'", "a boolean where a number")),
    ("quoted-in-list", "name: x\nworld: {x: ['0', 2000]}\n", ("'world.x'", "text where")),
    # field errors name the cross-field checks still to come
    ("field-and-cross", "name: x\nseed: -1\nenvironment: {wind: {speed_mps: 80}}\n",
     ("'seed'", "checks across fields", "run once these are fixed")),
]




@pytest.mark.parametrize(("text", "words"), [c[1:] for c in CORPUS], ids=[c[0] for c in CORPUS])
def test_hostile_scenario_exits_2_from_validate_and_run(
    tmp_path: Path, capsys: pytest.CaptureFixture[str], text: str | bytes, words: tuple[str, ...]
) -> None:
    path = tmp_path / "hostile.yaml"
    if isinstance(text, bytes):
        path.write_bytes(text)
    else:
        path.write_text(text, encoding="utf-8")
    out = tmp_path / "out"
    for argv in (["validate", str(path)], ["run", str(path), "--out", str(out), "--force"]):
        assert main(argv) == 2, argv
        captured = capsys.readouterr()
        err = captured.err
        assert str(path) in err, err
        assert "Traceback" not in err and "internal error" not in err
        assert "\x1b" not in err and "\x00" not in err  # nothing raw reaches the terminal
        assert len(err) < 4000, f"message of {len(err)} characters"
        for w in words:
            assert w in err, f"{w!r} not in:\n{err}"
        assert captured.out == ""
    assert not out.exists()


def test_billion_laughs_in_bounded_memory(tmp_path: Path) -> None:
    """Ten levels (10^10 strings once expanded): refused with little memory used. The child
    reports its own peak resident size."""
    path = tmp_path / "laughs.yaml"
    path.write_text(laughs(10))
    # VmHWM is this process's own peak; ru_maxrss of a forked child can carry its parent's.
    code = (
        "import re, sys; from uavxai.cli import main; "
        f"rc = main(['validate', {str(path)!r}]); "
        "peak = re.search(r'VmHWM:\\s+(\\d+)', open('/proc/self/status').read()).group(1); "
        "print(rc, peak)"
    )
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120)
    rc, peak_kb = proc.stdout.split()
    assert int(rc) == 2 and "aliases" in proc.stderr
    assert int(peak_kb) < 400_000, f"peak {int(peak_kb) / 1024:.0f} MB"


def test_merge_keys_and_reused_anchors_stay_allowed(tmp_path: Path) -> None:
    """Bounded, not banned: anchors for repeated intruders and merge keys that override a key
    (not a duplicate) are ordinary YAML."""
    path = tmp_path / "anchors.yaml"
    path.write_text(
        "name: anchors\n"
        "intruders:\n"
        "  list:\n"
        "    - &b {x: 400, y: 500, h: 120, heading_deg: 0, speed_mps: 20}\n"
        "    - {<<: *b, x: 600}\n"
        "    - {<<: *b, x: 800, speed_mps: 25}\n"
    )
    sc = load_scenario(path)
    assert [s.x for s in sc.intruders.list] == [400, 600, 800]
    assert [s.speed_mps for s in sc.intruders.list] == [20, 20, 25]


# ------------------------------------------------------------------------------------- fuzz
HOSTILE_VALUES: list[Any] = [
    None, True, 0, -1, 1, 7, 2**31, 10**30, -(10**30), 0.5, -0.0, 1e-9, 1e308, -1e308,
    math.inf, -math.inf, math.nan, "", "x", "uav_fw", "..", "a\x00b", "\x1b[31m", "1e3",
    "y" * 5000, [], [1], [1, 2], [2, 1], [0, 0], [1, 2, 3], [[1, 2]], [math.inf, 1], {},
    {"x": 1}, {"name": "n"}, [[1000, 1000]] * 3, [{"x": 1}],
    {"x": 500, "y": 500, "h": 120, "heading_deg": 0, "speed_mps": 20},
]


def _paths(node: Any, prefix: tuple = ()) -> list[tuple]:
    out = [prefix]
    if isinstance(node, dict):
        for k, v in node.items():
            out += _paths(v, (*prefix, k))
    elif isinstance(node, list):
        for i, v in enumerate(node):
            out += _paths(v, (*prefix, i))
    return out


def _mutate(data: dict, rng: random.Random) -> dict:
    data = copy.deepcopy(data)
    for _ in range(rng.randint(1, 3)):
        paths = [p for p in _paths(data) if p]
        if not paths:  # everything deleted: start again from a bare name
            data["name"] = rng.choice(HOSTILE_VALUES)
            continue
        path = rng.choice(paths)
        parent = data
        for part in path[:-1]:
            parent = parent[part]
        key = path[-1]
        roll = rng.random()
        if roll < 0.7:
            parent[key] = copy.deepcopy(rng.choice(HOSTILE_VALUES))
        elif roll < 0.8 and isinstance(parent, dict):
            del parent[key]
        elif roll < 0.9 and isinstance(parent, dict):
            parent[str(key) + rng.choice(["_", "s", ""]) + "x"] = 1  # an unknown key
        elif isinstance(parent[key], int | float) and not isinstance(parent[key], bool):
            parent[key] = parent[key] * rng.choice([-1, 10, 1e6, 1e-6])
        else:
            parent[key] = {"nested": parent[key]}
    return data


def _seeds() -> list[dict]:
    """Demo-like dicts: every key at its default, plus the shipped scenarios."""
    full = Scenario.model_validate({"name": "fuzz"}).model_dump(mode="json")
    shipped = [yaml.safe_load(p.read_text()) for p in sorted(scenarios_dir().glob("*.yaml"))]
    return [full, *shipped]


def test_schema_fuzz_gives_a_scenario_or_a_scenario_error(tmp_path: Path) -> None:
    rng = random.Random(20261123)
    seeds = _seeds()
    outcomes = {"valid": 0, "error": 0}
    for i in range(1500):
        data = _mutate(rng.choice(seeds), rng)
        try:
            sc = parse_scenario(data, f"fuzz-{i}")
        except ScenarioError as exc:
            msg = str(exc)
            assert msg.startswith(f"fuzz-{i}: ") and len(msg) < 4000
            outcomes["error"] += 1
        else:
            assert isinstance(sc, Scenario)
            outcomes["valid"] += 1
        if i % 10 == 0:  # and through the file loader, which has its own checks
            path = tmp_path / f"f{i}.yaml"
            try:
                path.write_text(yaml.safe_dump(data, allow_unicode=True))
            except (ValueError, UnicodeEncodeError):
                continue
            try:
                assert isinstance(load_scenario(path), Scenario)
            except ScenarioError as exc:
                assert str(path) in str(exc)
    assert outcomes["valid"] > 25 and outcomes["error"] > 1000, outcomes


def test_a_1_gb_scenario_is_refused_by_its_size_before_it_is_read(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    """A sparse 1 GB file: refused with the size message, and the reader allocates far less
    than the file (tracemalloc's peak, not the wall clock)."""
    import tracemalloc

    path = tmp_path / "huge.yaml"
    with path.open("wb") as f:
        f.write(b"name: x\n")
        f.truncate(1 << 30)
    tracemalloc.start()
    try:
        with pytest.raises(ScenarioError, match="1073741824 bytes is too large") as err:
            load_scenario(path)
        _, peak = tracemalloc.get_traced_memory()
    finally:
        tracemalloc.stop()
    assert str(path) in str(err.value) and "at most 256000 characters" in str(err.value)
    assert peak < 100 * 2**20, f"peak {peak / 2**20:.0f} MB"
    assert main(["validate", str(path)]) == 2
    assert "too large" in capsys.readouterr().err



def test_unquoted_exponent_numbers_are_numbers_and_the_shipped_scenarios_validate(
    tmp_path: Path,
) -> None:
    """YAML 1.2 numbers such as 1e3 (PyYAML would read text) stay numbers under the strict
    schema; every shipped scenario still validates."""
    path = tmp_path / "exp.yaml"
    path.write_text("name: x\navoidance: {goal_radius_m: 5e1}\nmission: {service_s: 1.2E2}\n")
    sc = load_scenario(path)
    assert sc.avoidance.goal_radius_m == 50.0 and sc.mission.service_s == 120.0
    shipped = sorted(scenarios_dir().glob("*.yaml"))
    assert shipped
    for f in shipped:
        load_scenario(f)
