"""docs/results/make_tables.py --daa: the issue-27 table is built from results.csv as written by
`uavxai evaluate` (the shipped campaign files), every metric with its interval."""

from __future__ import annotations

import csv
import importlib.util
import shutil
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
ENC = ROOT / "docs" / "results" / "encounters"


def _tables():
    path = ROOT / "docs" / "results" / "make_tables.py"
    spec = importlib.util.spec_from_file_location("make_tables", path)
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_daa_table_quotes_each_method_and_dynamics(tmp_path: Path) -> None:
    kin, jsb = tmp_path / "kinematic", tmp_path / "jsbsim"
    kin.mkdir(), jsb.mkdir()
    shutil.copy(ENC / "kinematic-interim2-results.csv", kin / "results.csv")
    shutil.copy(ENC / "jsbsim-none2k-results.csv", jsb / "results.csv")
    text = _tables().daa_table([kin / "results.csv", jsb / "results.csv"])
    with (kin / "results.csv").open() as f:
        daa = next(r for r in csv.DictReader(f) if r["method"] == "mcts_daa")
    row = next(line for line in text.splitlines() if line.startswith("| mcts_daa | kinematic"))
    rr = f"{float(daa['nmac_risk_ratio']):.3g} [{float(daa['nmac_risk_ratio_lo']):.3g}, "
    assert rr in row and f"| {int(daa['episodes']):,} |" in row and row.endswith("| wide |")
    # The side-by-side table pairs only methods flown in both dynamics: `none` here.
    side = text.split("\n\n")[1].splitlines()
    assert side[0].startswith("| method | NMAC risk ratio, kinematic | NMAC risk ratio, jsbsim")
    assert [line.split(" |")[0] for line in side[2:]] == ["| none"]


def test_multi_threat_table_quotes_the_mission_safety_and_daa_columns(tmp_path: Path) -> None:
    src = ROOT / "docs" / "results" / "manoeuvring" / "kinematic-mt20-daa50-results.csv"
    folder = tmp_path / "kinematic"
    folder.mkdir()
    shutil.copy(src, folder / "results.csv")
    text = _tables().multi_threat_table([folder / "results.csv"])
    with src.open() as f:
        rows = {r["method"]: r for r in csv.DictReader(f)}
    lines = text.splitlines()
    assert lines[0].startswith("| method | file | intruders | episodes | goal |")
    # none first, then in the DAA order, every method of the file once
    assert [ln.split(" |")[0].removeprefix("| ") for ln in lines[2:]] == [
        m for m in ("none", "mvp", "mcts", "mcts_vertical", "mcts_daa") if m in rows]
    daa = rows["mcts_daa"]
    row = next(ln for ln in lines if ln.startswith("| mcts_daa |"))
    assert f"| {float(daa['goal_rate']):.3f} | {float(daa['out_of_bounds_rate']):.3f} |" in row
    rr = f"{float(daa['nmac_risk_ratio']):.3g} [{float(daa['nmac_risk_ratio_lo']):.3g}, "
    assert rr in row
