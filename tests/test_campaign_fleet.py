"""`uavxai evaluate` of a fleet (issue 32, docs/fleet.md "Fleet campaigns"): episode i is the
fleet mission `uavxai run --seed` flies, by the same code (its trajectory.csv and service.csv
byte for byte); its fleet_episodes.csv row is that run's numbers, checked against its files
(delivered bits per user, QoS share and Jain fairness recomputed from service.csv, the members'
encounters from trajectory.csv); --resume and --workers give the same rows; the leave's
columns are the run's departure; bad requests are UserErrors. Real JSBSim and MCTS."""

from __future__ import annotations

import csv
import json
import math
import os
import shutil
from pathlib import Path

import pytest
import yaml

from uavxai.campaign import (
    FLEET_EPISODE_COLUMNS,
    FLEET_EPISODES,
    FLEET_RESULT_COLUMNS,
    FLEET_RESULTS,
    TIMING_COLUMNS,
    merge_campaigns,
    rerun_row,
    run_campaign,
    run_campaign_episode,
    run_fleet_episode,
    summarise_fleet,
)
from uavxai.campaign.files import as_written
from uavxai.campaign.fleet import RUNS, episode_folder
from uavxai.campaign.plots import FLEET_EPISODES_FIGURE, FLEET_RESULTS_FIGURE
from uavxai.cli import main
from uavxai.errors import UserError
from uavxai.journal import JOURNAL
from uavxai.outputs import OutputError
from uavxai.scenario import Scenario, load_scenario

FLEET_MISSION = Path(__file__).resolve().parents[1] / "scenarios" / "fleet-mission.yaml"
# Two members, six walking users, three intruders, 10 s on station: 3-6 s a flight.
SHORT = {
    "name": "fleet-short", "seed": 7, "fleet": {"size": 2}, "world": {"x": [-400, 2000]},
    "ownship": {"start": {"x": 150, "y": 1300, "h": 120, "heading_deg": 90, "speed_mps": 20}},
    "comms": {"access": "ofdma", "users": {"count": 6,
                                           "mobility": {"model": "random_waypoint"}}},
    "intruders": {"count": 3}, "mission": {"service_s": 10},
    "avoidance": {"max_steps": 40, "mcts": {"simulations": 60, "depth": 3}},
    "log": {"rerun": False},
}  # fmt: skip
EVALUATE = ["--methods", "mcts", "--intruders", "3", "--dynamics", "jsbsim"]


def _rows(path: Path) -> tuple[list[str], list[dict]]:
    with path.open() as f:
        reader = csv.DictReader(f)
        return list(reader.fieldnames or []), list(reader)


@pytest.fixture(scope="module")
def short(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("fleet-short") / "short.yaml"
    path.write_text(yaml.safe_dump(SHORT))
    return path


@pytest.fixture(scope="module")
def campaign(short: Path) -> Path:
    out = short.parent / "campaign"
    assert main(["evaluate", str(short), *EVALUATE, "--episodes", "2", "--out", str(out)]) == 0
    return out


@pytest.fixture(scope="module")
def runs(short: Path) -> dict[int, Path]:
    """`uavxai run --seed S` of each seed the campaign flew."""
    out = {}
    for seed in (7, 8):
        out[seed] = short.parent / f"run-{seed}"
        assert main(["run", str(short), "--seed", str(seed), "--out", str(out[seed])]) == 0
    return out


def test_a_fleet_campaign_writes_one_row_per_episode_and_its_results(campaign: Path) -> None:
    columns, rows = _rows(campaign / FLEET_EPISODES)
    assert tuple(columns) == FLEET_EPISODE_COLUMNS
    assert [(r["episode"], r["seed"], r["method"], r["intruders"]) for r in rows] == [
        ("0", "7", "mcts", "3"), ("1", "8", "mcts", "3")]  # fmt: skip
    assert not (campaign / "episodes.csv").exists()  # one ownship's columns: not a fleet's
    columns, (result,) = _rows(campaign / FLEET_RESULTS)
    assert tuple(columns) == FLEET_RESULT_COLUMNS
    completed = sum(int(r["completed"]) for r in rows)
    assert float(result["completed_rate"]) == pytest.approx(completed / 2)
    assert float(result["completed_rate_lo"]) <= completed / 2 <= float(result["completed_rate_hi"])
    # bits as whole numbers, not six digits of them
    assert int(result["min_delivered_bits"]) == min(int(r["delivered_bits"]) for r in rows)
    assert int(result["mean_delivered_bits"]) == round(
        sum(int(r["delivered_bits"]) for r in rows) / 2)  # fmt: skip
    assert float(result["min_closest_members_m"]) == pytest.approx(
        min(float(r["closest_members_m"]) for r in rows), rel=1e-5)  # fmt: skip
    for r in rows:
        assert (episode_folder(campaign, "mcts", 3, int(r["episode"])) / "summary.json").is_file()
    # computed from the rows as the file holds them: the file alone gives its results again
    (again,) = as_written(summarise_fleet(rows), FLEET_RESULT_COLUMNS)
    assert {k: str(v) for k, v in again.items()} == result


def test_the_committed_fleet_results_are_what_their_episodes_give() -> None:
    """Every fleet_results file under docs/results/fleet is what write_fleet_campaign computes
    from its episodes file, cell for cell (round 12's leave copy had been computed from the
    runs' unrounded numbers: mean_jain_fairness differed in the sixth digit)."""
    folder = Path(__file__).resolve().parents[1] / "docs" / "results" / "fleet"
    checked = 0
    for episodes_file in sorted(folder.glob("*_episodes.csv")):
        columns, rows = _rows(episodes_file)
        if tuple(columns) != FLEET_EPISODE_COLUMNS:
            continue  # a one-ownship campaign's
        _, results = _rows(episodes_file.with_name(
            episodes_file.name.replace("_episodes.csv", "_results.csv")))  # fmt: skip
        again = as_written(summarise_fleet(rows), FLEET_RESULT_COLUMNS)
        assert [{k: str(v) for k, v in r.items()} for r in again] == results, episodes_file
        checked += 1
    assert checked >= 2


def test_each_episode_is_the_run_of_its_seed(campaign: Path, runs: dict[int, Path]) -> None:
    """The same code path: the campaign's episode folder holds the run's own files, and the
    row is the run's summary."""
    _, rows = _rows(campaign / FLEET_EPISODES)
    for r in rows:
        seed, mine = int(r["seed"]), episode_folder(campaign, "mcts", 3, int(r["episode"]))
        run = runs[seed]
        for name in ("trajectory.csv", "service.csv", "users.csv"):
            assert (mine / name).read_bytes() == (run / name).read_bytes(), name
        s = json.loads((run / "summary.json").read_text())
        fleet, meet = s["fleet"], s["fleet_encounters"]
        assert r["outcome"] == s["outcome"]
        assert r["member_outcomes"] == " ".join(u["outcome"] for u in fleet)
        assert int(r["completed"]) == all(u["outcome"] == "completed" for u in fleet)
        assert int(r["delivered_bits"]) == round(s["mission"]["delivered_bits"])
        assert [float(b) for b in r["member_delivered_bits"].split()] == pytest.approx(
            [u["delivered_bits"] for u in fleet], abs=0.5)  # fmt: skip
        assert float(r["energy_wh"]) == pytest.approx(sum(u["energy_wh"] for u in fleet), 1e-5)
        assert float(r["qos_share"]) == pytest.approx(s["mission"]["qos_user_seconds_share"])
        assert float(r["jain_fairness"]) == pytest.approx(s["mission"]["jain_fairness"])
        for key in ("member_collisions", "intruder_collisions", "member_nmacs", "intruder_nmacs"):
            assert int(r[key]) == len(meet[key])
        assert float(r["closest_members_m"]) == pytest.approx(meet["closest_members_m"], 1e-5)
        assert float(r["closest_intruder_m"]) == pytest.approx(meet["closest_intruder_m"], 1e-5)


@pytest.fixture(scope="module")
def shards(short: Path) -> list[Path]:
    """The campaign's two seeds flown as two one-episode campaigns (`--seed`), as a campaign
    split over machines or days is."""
    out = []
    for seed in (7, 8):
        out.append(short.parent / f"shard-{seed}")
        args = ["evaluate", str(short), *EVALUATE, "--episodes", "1", "--seed", str(seed)]
        assert main([*args, "--out", str(out[-1])]) == 0
    return out


def _untimed(rows: list[dict]) -> list[dict]:
    return [{k: v for k, v in r.items() if k not in TIMING_COLUMNS} for r in rows]


def test_merged_shards_are_the_campaign_flown_whole(campaign: Path, shards: list[Path],
                                                    tmp_path: Path, capsys) -> None:  # fmt: skip
    """`uavxai merge` of the two shards, given in either order, writes the files of the
    two-episode campaign: fleet_episodes.csv and fleet_results.csv alike cell for cell but for
    the timing columns, each episode's run folder the same run under the whole campaign's
    number, and the figures the whole campaign's rows draw, pixel for pixel; merged again with
    a third, it refuses the seeds flown twice; a source without its run folders merges, and
    the command says how many it copied."""
    import matplotlib.image

    from uavxai.campaign.plots import plot_fleet

    whole = _rows(campaign / FLEET_EPISODES)[1]
    assert [r["seed"] for r in whole] == ["7", "8"]
    # the figures of the whole campaign's own rows, under the title merge gives its figures
    drawn = tmp_path / "drawn"
    drawn.mkdir()
    plot_fleet(_rows(campaign / FLEET_RESULTS)[1], whole, drawn, "merged from 2 campaigns")
    for order in (shards[::-1], shards):
        merged = tmp_path / "-".join(p.name for p in order)
        assert main(["merge", *map(str, order), "--out", str(merged)]) == 0
        printed = " ".join(capsys.readouterr().out.split())  # as the terminal wraps it
        assert "fleet campaign" in printed and "run files of 2 of the 2 episodes" in printed
        for name in (FLEET_EPISODES, FLEET_RESULTS):
            (columns, rows), (whole_columns, whole_rows) = (_rows(merged / name),
                                                            _rows(campaign / name))  # fmt: skip
            assert columns == whole_columns
            assert _untimed(rows) == _untimed(whole_rows), name
        for r in whole:
            mine = episode_folder(merged, "mcts", 3, int(r["episode"]))
            theirs = episode_folder(campaign, "mcts", 3, int(r["episode"]))
            for name in ("trajectory.csv", "service.csv", "users.csv"):
                assert (mine / name).read_bytes() == (theirs / name).read_bytes(), name
            assert json.loads((mine / "summary.json").read_text())["seed"] == int(r["seed"])
        assert sorted(p.name for p in (merged / RUNS).iterdir()) == sorted(
            p.name for p in (campaign / RUNS).iterdir())  # fmt: skip
        for figure in (FLEET_RESULTS_FIGURE, FLEET_EPISODES_FIGURE):
            image = matplotlib.image.imread(merged / figure)
            assert image.std() > 0.01  # not a blank page
            assert (image == matplotlib.image.imread(drawn / figure)).all(), figure
    # a source whose run folders stayed on the node that flew them (--ray): its rows merge
    bare = tmp_path / "bare"
    shutil.copytree(shards[1], bare, ignore=shutil.ignore_patterns(RUNS))
    assert main(["merge", str(shards[0]), str(bare), "--out", str(tmp_path / "part")]) == 0
    assert "run files of 1 of the 2 episodes" in " ".join(capsys.readouterr().out.split())
    assert [p.name for p in (tmp_path / "part" / RUNS).iterdir()] == [
        episode_folder(Path(), "mcts", 3, 0).name]  # seed 7's, from the source that has it
    # the same seed twice, never over a folder without --force, never a mix of kinds
    with pytest.raises(UserError, match=r"mcts at 3 intruders, seed 7: flown in both"):
        merge_campaigns([merged, shards[0]], tmp_path / "twice")
    assert main(["merge", *map(str, shards), "--out", str(merged)]) == 2
    one = tmp_path / "one-ownship"
    one.mkdir()
    with pytest.raises(UserError, match="has neither fleet_episodes.csv nor episodes.csv; is it"):
        merge_campaigns([shards[0], one], tmp_path / "mixed")
    (one / "episodes.csv").write_text("method\n")
    with pytest.raises(UserError, match=r"a fleet campaign \(fleet_episodes.csv\); .*not one"):
        merge_campaigns([shards[0], one], tmp_path / "mixed")
    assert not (tmp_path / "twice").exists() and not (tmp_path / "mixed").exists()


def test_merge_refuses_broken_fleet_files_by_name(shards: list[Path], capsys) -> None:
    """A source whose fleet_episodes.csv is empty, or holds what a campaign never writes: a
    clear message (exit 2), no traceback, no files."""
    broken = shards[0].parent / "broken"
    broken.mkdir()
    header, row = (shards[0] / FLEET_EPISODES).read_text().splitlines()
    (broken / FLEET_EPISODES).write_text(header + "\n")
    out = shards[0].parent / "from-broken"
    assert main(["merge", str(broken), "--out", str(out)]) == 2
    err = capsys.readouterr().err
    assert "no episodes in their fleet_episodes.csv" in err and "Traceback" not in err
    assert not (out / FLEET_RESULTS).exists()
    out = shards[0].parent / "from-broken-python"
    cells = row.split(",")
    # what a campaign never writes: counts below 0, empty or 'inf' (summed, they crashed the
    # merge or merged as nonsense), shares above 1, a closest approach below 0
    for column, bad in (("completed", "2"), ("qos_share", "most"), ("seed", "-1"),
                        ("member_collisions", "-3"), ("member_collisions", ""),
                        ("intruder_nmacs", "inf"), ("departures", "1.5"), ("qos_share", "7"),
                        ("jain_fairness", "-0.1"), ("leave_qos_share_after", "1.2"),
                        ("delivered_bits", "-1"), ("closest_members_m", "-1")):  # fmt: skip
        wrong = list(cells)
        wrong[FLEET_EPISODE_COLUMNS.index(column)] = bad
        (broken / FLEET_EPISODES).write_text(header + "\n" + ",".join(wrong) + "\n")
        with pytest.raises(UserError, match=rf"line 2: {column} '{bad}' is not allowed"):
            merge_campaigns([broken], out)
    assert not out.exists()


def test_merge_copies_run_folders_but_follows_no_link(shards: list[Path], tmp_path: Path) -> None:
    """A link inside a source's run folder is copied as a link (what it points to is not read
    into the merged folder); a run folder that is itself a link is not copied, and the rows
    are merged all the same."""
    outside = tmp_path / "outside.txt"
    outside.write_text("not the campaign's")
    linked = tmp_path / "linked"
    shutil.copytree(shards[0], linked)
    run = episode_folder(linked, "mcts", 3, 0)
    (run / "secret").symlink_to(outside)
    merge_campaigns([linked], tmp_path / "m1")
    copied = episode_folder(tmp_path / "m1", "mcts", 3, 0)
    assert (copied / "secret").is_symlink() and (copied / "trajectory.csv").is_file()
    shutil.rmtree(run)
    run.symlink_to(episode_folder(shards[0], "mcts", 3, 0), target_is_directory=True)
    merge_campaigns([linked], tmp_path / "m2")
    assert not episode_folder(tmp_path / "m2", "mcts", 3, 0).exists()
    assert _rows(tmp_path / "m2" / FLEET_EPISODES) == _rows(tmp_path / "m1" / FLEET_EPISODES)
    # nor is a fleet-runs folder that is itself a link (its run folders are real ones)
    shutil.rmtree(linked / RUNS)
    (linked / RUNS).symlink_to(shards[0] / RUNS, target_is_directory=True)
    merge_campaigns([linked], tmp_path / "m3")
    assert not (tmp_path / "m3" / RUNS).exists()
    assert _rows(tmp_path / "m3" / FLEET_EPISODES) == _rows(tmp_path / "m1" / FLEET_EPISODES)


def _shard_copy(shard: Path, to: Path) -> tuple[Path, Path]:
    """A copy of a one-episode shard and its run folder's summary.json."""
    shutil.copytree(shard, to)
    return to, episode_folder(to, "mcts", 3, 0) / "summary.json"


def test_merge_copies_only_files_and_names_what_it_cannot_copy(shards: list[Path],
                                                               tmp_path: Path) -> None:  # fmt: skip
    """A FIFO in a run folder is left out (it failed the whole copy, as "internal error");
    a run folder that cannot be copied is an OutputError naming it, and what was in --out
    before stays."""
    src, _ = _shard_copy(shards[0], tmp_path / "fifo")
    os.mkfifo(episode_folder(src, "mcts", 3, 0) / "pipe")
    merge_campaigns([src], tmp_path / "m")
    copied = episode_folder(tmp_path / "m", "mcts", 3, 0)
    assert (copied / "summary.json").is_file() and not os.path.lexists(copied / "pipe")
    there = episode_folder(tmp_path / "taken", "mcts", 3, 0)
    there.mkdir(parents=True)
    (there / "mine").write_text("kept")
    with pytest.raises(OutputError, match=r"cannot copy .* it exists") as err:
        merge_campaigns([shards[0]], tmp_path / "taken")
    assert err.value.folder == tmp_path / "taken"
    assert [p.name for p in there.iterdir()] == ["mine"]


def test_merge_refuses_run_folders_that_are_not_their_rows(shards: list[Path],
                                                           tmp_path: Path) -> None:  # fmt: skip
    """A run folder whose summary.json is another episode's (seed, planner, intruder count)
    or missing, an episode numbered twice in one source: refused naming both sides (they were
    merged as the row's before)."""
    for key, value, says in (("seed", 99, "seed 99, planner mcts"),
                             ("avoidance_planner", "none", "planner none"),
                             ("intruders", 9, "8 intruders")):  # fmt: skip
        src, summary_file = _shard_copy(shards[0], tmp_path / f"wrong-{key}")
        summary = json.loads(summary_file.read_text())
        summary[key] = value
        summary_file.write_text(json.dumps(summary))
        with pytest.raises(UserError, match=rf"{says}.*but its row .* is seed 7, planner mcts, "
                                            r"3 intruders, 2 members"):  # fmt: skip
            merge_campaigns([src], tmp_path / "out")
    summary_file.unlink()
    with pytest.raises(UserError, match=r"summary.json: cannot read it as the summary"):
        merge_campaigns([src], tmp_path / "out")
    # the same episode number twice in one source (another seed: not caught as a seed twice)
    src, _ = _shard_copy(shards[0], tmp_path / "twice")
    header, row = (src / FLEET_EPISODES).read_text().splitlines()
    cells = row.split(",")
    cells[FLEET_EPISODE_COLUMNS.index("seed")] = "8"
    (src / FLEET_EPISODES).write_text("\n".join([header, row, ",".join(cells)]) + "\n")
    with pytest.raises(UserError, match=r"line 3: mcts at 3 intruders, episode 0 again \(line 2"):
        merge_campaigns([src], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_merge_refuses_fleets_of_other_sizes_or_scenarios(shards: list[Path],
                                                          tmp_path: Path) -> None:  # fmt: skip
    """Rows of a fleet of three beside a fleet of two, runs of another scenario: refused
    naming both (they were pooled before)."""
    three, _ = _shard_copy(shards[1], tmp_path / "three")
    shutil.rmtree(three / RUNS)  # no run folder to tell: the rows alone
    header, row = (three / FLEET_EPISODES).read_text().splitlines()
    cells = row.split(",")
    cells[FLEET_EPISODE_COLUMNS.index("member_outcomes")] += " completed"
    (three / FLEET_EPISODES).write_text(header + "\n" + ",".join(cells) + "\n")
    with pytest.raises(UserError, match=r"fleets of different sizes \(members: .*: 2; .*: 3\)"):
        merge_campaigns([shards[0], three], tmp_path / "out")
    other, summary_file = _shard_copy(shards[1], tmp_path / "other")
    summary = json.loads(summary_file.read_text())
    summary["scenario"] = "another"
    summary_file.write_text(json.dumps(summary))
    with pytest.raises(UserError, match=r"different scenarios or dynamics .*fleet-short.*another"):
        merge_campaigns([shards[0], other], tmp_path / "out")
    assert not (tmp_path / "out").exists()


def test_merge_force_never_empties_a_source_nor_a_merge_it_refuses(
    shards: list[Path], tmp_path: Path, capsys
) -> None:
    """--force over a folder that holds a source is refused (it emptied the folder, source
    and all, before reading it); a source refused leaves the previous merge as it was."""
    merged = tmp_path / "merged"
    assert main(["merge", *map(str, shards), "--out", str(merged)]) == 0
    inner, _ = _shard_copy(shards[0], merged / "inner")
    assert main(["merge", str(inner), str(shards[1]), "--out", str(merged), "--force"]) == 2
    assert "holds the source" in capsys.readouterr().err
    assert (inner / FLEET_EPISODES).is_file()
    shutil.rmtree(inner)
    broken, _ = _shard_copy(shards[1], tmp_path / "broken")
    header, row = (broken / FLEET_EPISODES).read_text().splitlines()
    cells = row.split(",")
    cells[FLEET_EPISODE_COLUMNS.index("qos_share")] = "7"
    (broken / FLEET_EPISODES).write_text(header + "\n" + ",".join(cells) + "\n")
    before = {p.name: p.read_bytes() for p in merged.iterdir() if p.is_file()}
    assert main(["merge", str(shards[0]), str(broken), "--out", str(merged), "--force"]) == 2
    assert "qos_share '7' is not allowed" in capsys.readouterr().err
    assert {p.name: p.read_bytes() for p in merged.iterdir() if p.is_file()} == before
    assert len(list((merged / RUNS).iterdir())) == 2


def test_the_runs_service_figures_are_recomputed_from_service_csv(runs: dict[int, Path]) -> None:
    sc = load_scenario(runs[7].parent / "short.yaml")
    dt, k, qos = 1.0 / sc.dynamics.trajectory_hz, sc.comms.users.k, sc.comms.qos_rate_bps
    for run in runs.values():
        mission = json.loads((run / "summary.json").read_text())["mission"]
        bits, hits, served = [0.0] * k, 0, set()
        for row in csv.DictReader((run / "service.csv").open()):
            rate = float(row["rate_bps"])
            bits[int(row["user"])] += rate * dt
            hits += rate >= qos
            served.add(row["t"])
        assert bits == pytest.approx(mission["delivered_bits_per_user"], rel=1e-6)
        assert sum(bits) == pytest.approx(mission["delivered_bits"], rel=1e-6)
        jain = sum(bits) ** 2 / (k * sum(b * b for b in bits))
        assert mission["jain_fairness"] == pytest.approx(jain, rel=1e-6)
        # over the samples any UAV served, a user no UAV serves counting as below QoS
        assert mission["qos_user_seconds_share"] == pytest.approx(hits / (k * len(served)))


def test_the_members_encounters_hold_what_trajectory_csv_shows(runs: dict[int, Path]) -> None:
    """Closest approaches between samples (the judge's rule) are at most the sampled ones,
    and not by more than the aircraft can close in half a sample; every NMAC the samples show
    is counted."""
    sc = load_scenario(runs[7].parent / "short.yaml")
    h, v = sc.avoidance.nmac.horizontal_m, sc.avoidance.nmac.vertical_m
    for run in runs.values():
        meet = json.loads((run / "summary.json").read_text())["fleet_encounters"]
        at: dict[str, dict[str, tuple[float, float, float]]] = {}
        for row in csv.DictReader((run / "trajectory.csv").open()):
            at.setdefault(row["t"], {})[row["id"]] = (float(row["x"]), float(row["y"]),
                                                       float(row["h"]))  # fmt: skip
        closest = {True: math.inf, False: math.inf}
        seen: set[tuple[str, str]] = set()
        for pos in at.values():
            members = sorted(i for i in pos if i.startswith("ownship"))
            for n, a in enumerate(members):
                for b in [*members[n + 1 :], *(i for i in pos if not i.startswith("ownship"))]:
                    d = math.dist(pos[a], pos[b])
                    fellow = b.startswith("ownship")
                    closest[fellow] = min(closest[fellow], d)
                    (xa, ya, ha), (xb, yb, hb) = pos[a], pos[b]
                    if math.hypot(xa - xb, ya - yb) < h and abs(ha - hb) < v:
                        seen.add((a, b))
        for fellow, key in ((True, "closest_members_m"), (False, "closest_intruder_m")):
            assert -1e-3 <= closest[fellow] - meet[key] <= 5.0, key  # rounded to mm
        nmacs = {tuple(p) for p in meet["member_nmacs"] + meet["intruder_nmacs"]}
        assert seen <= nmacs


def test_resume_and_workers_give_the_same_rows(short: Path, campaign: Path,
                                               tmp_path: Path) -> None:  # fmt: skip
    """--resume with one more episode flies only it (the journaled rows kept, their wall time
    too); two workers fly the first two to the same rows. Resumed in a copy: the module's
    campaign stays the two-episode one the other tests read, whatever their order."""
    campaign = shutil.copytree(campaign, tmp_path / "campaign")
    before = _rows(campaign / FLEET_EPISODES)[1]
    args = ["evaluate", str(short), *EVALUATE, "--episodes", "3", "--out", str(campaign)]
    assert main([*args, "--resume"]) == 0
    after = _rows(campaign / FLEET_EPISODES)[1]
    assert after[:2] == before and after[2]["seed"] == "9"
    journal = [json.loads(line) for line in (campaign / JOURNAL).read_text().splitlines()[1:]]
    assert [r["episode"] for r in journal] == [0, 1, 2]  # none flown twice
    pooled = run_campaign(load_scenario(short), ["mcts"], [3], 2, dynamics="jsbsim", workers=2)
    assert _untimed(pooled) == _untimed(sorted(journal, key=lambda r: r["episode"])[:2])


def test_a_member_leaving_early_fills_the_leave_columns(tmp_path: Path) -> None:
    leave = {**SHORT, "fleet": {"size": 2, "leave": {"member": 1, "at_s": 30}},
             "mission": {"service_s": 20}}  # fmt: skip
    path = tmp_path / "leave.yaml"
    path.write_text(yaml.safe_dump(leave))
    row = run_fleet_episode(load_scenario(path), "mcts", 3, 7, tmp_path / "run")
    (gone,) = json.loads((tmp_path / "run" / "summary.json").read_text())["fleet_departures"]
    assert row["departures"] == 1 and row["leave_uav"] == gone["uav"] == 1
    assert row["leave_t_s"] == pytest.approx(30, abs=0.2)
    for key in ("qos_share_before", "qos_share_after", "crowd_qos_share_before",
                "crowd_qos_share_after"):  # fmt: skip
        assert row[f"leave_{key}"] == pytest.approx(gone[key]), key
    # the leave's worst case beside its mean: the lowest share after, the slowest recovery,
    # and the departures never recovered (a copy of the row that never recovered)
    never = {**row, "seed": 8, "leave_qos_share_after": 0.25, "leave_recovered_after_s": None}
    slow = {**row, "seed": 9, "leave_qos_share_after": 0.5, "leave_recovered_after_s": 1e4}
    (result,) = summarise_fleet([row, never, slow])
    assert result["min_leave_qos_share_after"] == 0.25
    assert result["mean_leave_qos_share_after"] == pytest.approx(
        (row["leave_qos_share_after"] + 0.75) / 3)  # fmt: skip
    assert result["max_leave_recovered_after_s"] == 1e4
    assert result["leave_never_recovered"] == 1 + (row["leave_recovered_after_s"] is None)


def test_a_fleet_campaign_opens_no_external_link(tmp_path: Path) -> None:
    """A scenario with a link (bridge.mavlink to a listening peer, a signing key, a ground
    station, link.tlog on): the campaign's episode connects to no one, writes no link.tlog,
    and its row is the row of the same scenario without the link."""
    import socket

    peer = socket.socket()  # a peer the link would connect to; no one may arrive
    peer.bind(("127.0.0.1", 0))
    peer.listen(4)
    peer.setblocking(False)
    port = peer.getsockname()[1]
    linked = {**SHORT, "bridge": {"mavlink": f"tcp:127.0.0.1:{port}", "tlog": True,
                                  "signing_key_hex": "ab" * 32,
                                  "ground_stations": [{"system_id": 255}]}}  # fmt: skip
    path = tmp_path / "linked.yaml"
    path.write_text(yaml.safe_dump(linked))
    plain = tmp_path / "plain.yaml"
    plain.write_text(yaml.safe_dump(SHORT))
    try:
        row = run_fleet_episode(load_scenario(path), "mcts", 3, 7, tmp_path / "linked")
        with pytest.raises(BlockingIOError):
            peer.accept()
    finally:
        peer.close()
    assert not list((tmp_path / "linked").rglob("*.tlog"))
    assert json.loads((tmp_path / "linked" / "summary.json").read_text())["bridge"] is not None
    alone = run_fleet_episode(load_scenario(plain), "mcts", 3, 7, tmp_path / "plain")
    assert _untimed([row]) == _untimed([alone])
    for name in ("trajectory.csv", "service.csv"):
        assert (tmp_path / "linked" / name).read_bytes() == (tmp_path / "plain" / name).read_bytes()


def test_bad_fleet_campaigns_are_user_errors(campaign: Path, capsys) -> None:
    """The kinematic world has no members: refused by name (it flew one ownship to a one-UAV
    service point before, silently); a count the scenario cannot take."""
    args = ["evaluate", str(FLEET_MISSION), "--methods", "mcts", "--intruders", "20"]
    assert main([*args, "--episodes", "1", "--out", str(campaign.parent / "kinematic")]) == 2
    err = capsys.readouterr().err
    assert "fleet.size = 3" in err and "--dynamics jsbsim" in err and "Traceback" not in err
    with pytest.raises(UserError, match=r"--intruders 501.*\(intruders\.count: "):
        run_campaign(load_scenario(FLEET_MISSION), ["mcts"], [501], 1, dynamics="jsbsim")
    # what `uavxai run` asks before flying: a learned service planner with no shipped model
    unshipped = {**SHORT, "service": {"planner": "d3qn"},
                 "comms": {**SHORT["comms"], "power_levels": 4}}  # fmt: skip
    with pytest.raises(UserError, match="power_levels = 4"):
        run_campaign(Scenario.model_validate(unshipped), ["mcts"], [3], 1, dynamics="jsbsim")
    # from Python: one ownship's episode of a fleet scenario, refused pointing to the fleet's
    with pytest.raises(UserError, match=r"fleet.size = 3.*run_fleet_episode"):
        run_campaign_episode(load_scenario(FLEET_MISSION), "mcts", 20, 0, "jsbsim")
    with pytest.raises(UserError, match=r"fleet.size = 3.*run_fleet_episode"):
        rerun_row(FLEET_MISSION, "mcts", 20, 0, "jsbsim")


def test_fleet_encounters_count_pairs_between_samples_by_the_judges_rules() -> None:
    """Members 0 and 1 pass through each other between two samples (neither sample shows
    it: 200 m apart before and after): a collision and an NMAC; member 1 comes 100 m from
    intruder-1 at one height (an NMAC, no collision) over two pieces: one pair, counted once;
    member 0 passes 179 m from it (no NMAC); intruder-2 stays 1 km away."""
    import numpy as np

    from uavxai.dynamics.state import TrafficState
    from uavxai.sim.fleet_record import FleetEncounters

    ids = ("ownship-0", "intruder-1", "intruder-2", "ownship-1")

    def state(t: float, xyz: list[tuple[float, float, float]]) -> TrafficState:
        n = len(xyz)
        return TrafficState(t, ids, np.array(xyz, dtype=float), np.zeros((n, 3)),
                            np.zeros((n, 3)), np.full(n, 20.0))  # fmt: skip

    class Start:  # what on_start reads of the episode: its state at the start
        pass

    start = Start()
    start.state = state(0.0, [(0, 0, 100), (700, 100, 100), (0, 1000, 100), (200, 0, 100)])
    meet = FleetEncounters(d_min_m=50.0, nmac_m=(152.4, 30.48))
    meet.on_start(start)  # type: ignore[arg-type]
    for t, xyz in [
        (0.1, [(200, 0, 100), (600, 100, 100), (0, 1000, 100), (0, 0, 100)]),  # swapped
        (0.2, [(300, 0, 100), (500, 100, 100), (0, 1000, 100), (500, 0, 100)]),
        (0.3, [(400, 0, 100), (400, 200, 100), (0, 1000, 100), (500, 0, 100)]),
    ]:
        meet.on_sample(None, state(t, xyz))  # type: ignore[arg-type]
    s = meet.section()
    assert s["member_collisions"] == [["ownship-0", "ownship-1"]]
    assert s["member_nmacs"] == [["ownship-0", "ownship-1"]]
    assert s["closest_members_m"] == 0.0
    assert s["intruder_nmacs"] == [["ownship-1", "intruder-1"]]
    assert s["intruder_collisions"] == []
    assert s["closest_intruder_m"] == pytest.approx(100.0)


def test_fleet_encounters_and_the_judge_agree_on_a_replaced_rows_sample() -> None:
    """Members 0 and 1 pass through each other (200 m apart before and after) in the sample
    in which intruder-1 is replaced (persistent traffic): the judge (member 0's) and the
    fleet's encounters both say collision and NMAC at 0 m (the encounters restarted every
    pair on any replacement before: 200 m, none); the newcomer, now 100 m above the point
    both members flew through, is judged where it is (141 m from each), not as if it had
    stood there all along (100 m)."""
    import numpy as np

    from uavxai.dynamics.state import TrafficState
    from uavxai.scenario import default_scenario
    from uavxai.sim.fleet_record import FleetEncounters
    from uavxai.sim.judge import Judge

    def state(t: float, ids: tuple[str, ...], xyz: list) -> TrafficState:
        z = np.zeros((len(xyz), 3))
        return TrafficState(t, ids, np.array(xyz, dtype=float), z, z, np.full(len(xyz), 20.0))

    prev = state(0.0, ("ownship-0", "intruder-1", "ownship-1"),
                 [(0, 0, 100), (0, 900, 100), (200, 0, 100)])  # fmt: skip
    now = state(0.1, ("ownship-0", "intruder-4", "ownship-1"),
                [(200, 0, 100), (100, 0, 200), (0, 0, 100)])  # fmt: skip

    class Start:  # what on_start reads of the episode: its state at the start
        state = prev

    meet = FleetEncounters(d_min_m=50.0, nmac_m=(152.4, 30.48))
    meet.on_start(Start())  # type: ignore[arg-type]
    meet.on_sample(None, now)  # type: ignore[arg-type]
    s = meet.section()
    judge = Judge(default_scenario("f").world, 50.0, None, 50.0, nmac_m=(152.4, 30.48))
    assert judge.separation(prev, now) == s["closest_members_m"] == 0.0
    assert judge.nmac(prev, now)
    assert s["member_collisions"] == s["member_nmacs"] == [["ownship-0", "ownship-1"]]
    assert s["closest_intruder_m"] == pytest.approx(math.hypot(100, 100), abs=1e-3)
    assert s["intruder_collisions"] == s["intruder_nmacs"] == []

