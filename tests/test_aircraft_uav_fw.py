"""The uav_fw JSBSim model: loadable from our aircraft path, silent, airworthy."""

from __future__ import annotations

import math
import os
import subprocess
import sys
import textwrap
import xml.etree.ElementTree as ET

import jsbsim
import pytest

from uavxai.dynamics.aircraft import Aircraft
from uavxai.dynamics.fdm import load_fdm
from uavxai.dynamics.geodesy import LocalFrame
from uavxai.errors import UserError
from uavxai.paths import aircraft_dir

FRAME = LocalFrame(34.123, 108.837, 400.0)
DT = 1.0 / 120.0
KG = 0.45359237  # per pound


def _xml_files() -> list:
    return sorted((aircraft_dir() / "uav_fw").rglob("*.xml"))


def test_model_files_declare_no_output() -> None:
    # <output> inside a component names the property it writes; a data-logging or socket
    # output is an <output> element with a type, at the top of a file.
    files = _xml_files()
    assert len(files) >= 4  # airframe, motor, propeller, autopilot
    for path in files:
        root = ET.parse(path).getroot()
        assert root.find("output") is None, path
        assert not [el for el in root.iter("output") if el.get("type")], path


def test_loads_with_our_aircraft_path_only() -> None:
    fdm = load_fdm("uav_fw", DT)
    assert fdm.get_model_name() == "uav_fw"
    assert os.path.samefile(fdm.get_aircraft_path(), aircraft_dir())
    mass_kg = fdm["inertia/weight-lbs"] * KG
    assert 5.0 <= mass_kg <= 15.0
    assert fdm.get_delta_t() == pytest.approx(DT)


def test_unknown_aircraft_is_a_user_error() -> None:
    with pytest.raises(UserError, match="known: .*uav_fw"):
        load_fdm("no_such_plane", DT)


def test_loading_and_flying_print_nothing(tmp_path) -> None:
    # fd-level: JSBSim writes from C++, which capsys would not see.
    code = textwrap.dedent(
        """
        from uavxai.scenario import default_scenario
        from uavxai.dynamics.world import JSBSimWorld
        w = JSBSimWorld(default_scenario("quiet", intruders={"count": 3}))
        w.advance(2.0)
        w.close()
        """
    )
    env = {k: v for k, v in os.environ.items() if k != "JSBSIM_DEBUG"}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, cwd=tmp_path, env=env, check=True
    )
    assert out.stdout == b""
    assert out.stderr == b""
    assert list(tmp_path.iterdir()) == []  # and writes no files


def test_jsbsim_warnings_reach_python_logging(caplog) -> None:
    # 45 m/s is beyond the top speed, so the trim fails: JSBSim complains, we log it.
    a = Aircraft("uav_fw", FRAME, DT, seed=1)
    with caplog.at_level("DEBUG"):
        trimmed = a.start(0.0, 0.0, 100.0, 0.0, 45.0)
    assert not trimmed
    assert any(r.name == "uavxai.jsbsim" and "trim" in r.getMessage() for r in caplog.records)
    a.close()


@pytest.mark.parametrize("speed", [12.0, 15.0, 20.0, 25.0, 30.0])
def test_trims_across_the_speed_range(speed: float) -> None:
    a = Aircraft("uav_fw", FRAME, DT, seed=1)
    assert a.start(0.0, 0.0, 100.0, 0.0, speed)
    f = a.fdm
    assert 0.0 < f["fcs/throttle-cmd-norm"] < 1.0
    for _ in range(240):  # 2 s: steady flight needs no correction
        a.run()
    assert f["velocities/vt-fps"] * 0.3048 == pytest.approx(speed, abs=0.2)
    assert f["velocities/h-dot-fps"] * 0.3048 == pytest.approx(0.0, abs=0.2)
    assert abs(f["attitude/phi-rad"]) < math.radians(0.5)
    a.close()


def test_cruise_and_stall_figures() -> None:
    # Stall below 12 m/s: at 12 m/s the trimmed angle of attack is below the stall angle of
    # the lift table (alpha at CL_max), with margin.
    a = Aircraft("uav_fw", FRAME, DT, seed=1)
    assert a.start(0.0, 0.0, 100.0, 0.0, 12.0)
    alpha_clmax = a.fdm["aero/alpha-max-rad"]
    assert a.fdm["aero/alpha-rad"] < alpha_clmax - math.radians(3)
    a.close()
    # Cruise at 20 m/s needs a fraction of the motor's power; 30 m/s is within reach.
    a = Aircraft("uav_fw", FRAME, DT, seed=1)
    a.start(0.0, 0.0, 100.0, 0.0, 20.0)
    assert a.fdm["fcs/throttle-cmd-norm"] < 0.4
    a.close()
    a = Aircraft("uav_fw", FRAME, DT, seed=1)
    a.start(0.0, 0.0, 100.0, 0.0, 30.0)
    assert a.fdm["fcs/throttle-cmd-norm"] < 0.9
    a.close()


def test_autopilot_components_are_named_jsbsim_components() -> None:
    root = ET.parse(aircraft_dir() / "uav_fw" / "Systems" / "uav_fw_autopilot.xml").getroot()
    names = {el.get("name") for el in root.iter() if el.get("name")}
    for needed in (
        "ap/roll-rate-pi",
        "ap/elevator-pi",
        "ap/throttle-pi",
        "ap/rudder-ball-pi",
        "ap/speed-target-next-mps",
        "ap/aileron-cmd-norm",
        "ap/elevator-cmd-norm",
        "ap/rudder-cmd-norm",
        "ap/throttle-cmd-norm",
    ):
        assert needed in names
    assert {el.tag for el in root.iter()} >= {"pid", "pure_gain", "summer", "switch"}


def test_autopilot_disengaged_outputs_nothing() -> None:
    a = Aircraft("uav_fw", FRAME, DT, seed=1)
    a.start(0.0, 0.0, 100.0, 0.0, 20.0)
    a.fdm["ap/engaged"] = 0.0
    a.command(bank_cmd_rad=0.5)
    for _ in range(12):
        a.run()
    for out in ("aileron", "elevator", "rudder", "throttle"):
        assert a.fdm[f"ap/{out}-cmd-norm"] == 0.0
    a.close()


def test_jsbsim_version_is_supported() -> None:
    major, minor = (int(x) for x in jsbsim.__version__.split(".")[:2])
    assert (major, minor) >= (1, 2)
