"""`uavxai merge`: campaigns of one scenario pooled into one, every results row computed again
from the pooled episodes; one-ownship campaigns (``episodes.csv``) or fleet campaigns
(``fleet_episodes.csv``, docs/fleet.md "Fleet campaigns"), not a mix.
"""

from __future__ import annotations

import contextlib
import json
import math
import os
import shutil
import stat
from collections.abc import Callable, Sequence
from pathlib import Path

from uavxai.campaign.files import (
    DAA_EPISODE_COLUMNS,
    EPISODE_COLUMNS,
    FLEET_EPISODE_COLUMNS,
    FLEET_EPISODES,
    FLIGHT_COLUMNS,
    GOAL_COLUMNS,
    RESULT_COLUMNS,
    checked_fleet_row,
    checked_row,
    columns_of,
    has_daa_columns,
    read_rows,
    write_csv,
)
from uavxai.campaign.fleet import RUNS, episode_folder, write_fleet_campaign
from uavxai.campaign.plots import plot_campaign, plot_fleet
from uavxai.campaign.statistics import summarise
from uavxai.errors import UserError
from uavxai.outputs import NO_SPACE, OutputError, cell_number, output_error
from uavxai.processes import interrupts_deferred


def is_fleet_campaign(src: Path) -> bool:
    """A campaign folder of a fleet (``fleet_episodes.csv``, no ``episodes.csv``)."""
    return (src / FLEET_EPISODES).is_file() and not (src / "episodes.csv").exists()


def merge_campaigns(sources: Sequence[str | Path], out: str | Path, title: str = "") -> list[dict]:
    """One campaign from several of the same scenario: one-ownship campaigns
    (:func:`merge_ownship`) or fleet campaigns (:func:`merge_fleet`), refused when mixed (their
    episodes are not the same thing). Its results rows."""
    return read_merge(sources)(Path(out), title)


Writer = Callable[[Path, str], list[dict]]


def read_merge(sources: Sequence[str | Path]) -> Writer:
    """Every source read and checked, nothing written: the function that then writes the
    merged campaign into a folder (with a title for its plots) and returns its results rows.
    `uavxai merge` reads first, so that a source it refuses leaves ``--out`` (and the previous
    merge in it, under ``--force``) as it was."""
    sources = [Path(s) for s in sources]
    fleets = [s for s in sources if is_fleet_campaign(s)]
    if fleets and len(fleets) < len(sources):
        one = next(s for s in sources if s not in fleets)
        if not (one / "episodes.csv").is_file():
            raise UserError(f"{one}: has neither {FLEET_EPISODES} nor episodes.csv; is it a "
                            "campaign folder?")  # fmt: skip
        raise UserError(
            f"{fleets[0]}: a fleet campaign ({FLEET_EPISODES}); {one}: not one (one ownship's "
            "campaign has episodes.csv); merge pools campaigns of one kind, fleet campaigns "
            "together or one-ownship campaigns together."
        )
    return (merge_fleet if fleets else merge_ownship)(sources)


def merge_ownship(sources: Sequence[Path]) -> Writer:
    """The writer (:func:`read_merge`) of one campaign from several of the same scenario and
    dynamics: other methods, other intruder counts, or more seeds of the same ones (a campaign
    extended later, or split over machines). The episodes are pooled and every ``results.csv``
    row is computed again from them, so a risk ratio pairs a method with ``none`` on every seed
    both flew, whichever source flew it. The same (method, intruders, seed) in two sources is an
    error: it would count twice.

    ``decision_ms_p50`` is the source's when one source flew the whole row; a pooled row has
    only each episode's median to go on and takes the median of those."""
    episodes: list[dict] = []
    flown_by: dict[tuple[str, int, int], Path] = {}
    p50: dict[tuple[str, int], float] = {}
    goals: dict[tuple[str, ...], Path] = {}
    for src in map(Path, sources):
        # files written before the goal was recorded lack its columns, and are taken on trust
        rows = read_rows(src / "episodes.csv", EPISODE_COLUMNS[: -len(GOAL_COLUMNS)])
        rows = [checked_row(r, src / "episodes.csv", i) for i, r in enumerate(rows, start=2)]
        for i, r in enumerate(rows, start=2):
            try:
                if has_daa_columns(r):  # the detect-and-avoid record's columns
                    if not 0 < float(r["weight"]) < math.inf:
                        raise ValueError
                    for column in DAA_EPISODE_COLUMNS[1:]:
                        cell_number(r.get(column))
            except (TypeError, ValueError):
                raise UserError(
                    f"{src / 'episodes.csv'} line {i}: in a detect-and-avoid record "
                    f"{', '.join(DAA_EPISODE_COLUMNS)} must be numbers, the weight > 0."
                ) from None
        for r in rows:
            for column in FLIGHT_COLUMNS:  # not in files written before they existed
                r.setdefault(column, "")
            _flown_once(r, src, flown_by)
            goal = tuple(r[k] for k in GOAL_COLUMNS)
            if any(g != "" for g in goal):
                goals.setdefault(goal, src)
        episodes.extend(rows)
        for r in read_rows(src / "results.csv", RESULT_COLUMNS):
            # garbage timing: nothing to keep, the row's own median of medians stands
            with contextlib.suppress(ValueError, OverflowError):
                ms = float(r["decision_ms_p50"] or "nan")
                if math.isfinite(ms) and ms >= 0:
                    p50[(r["method"], int(r["intruders"]))] = ms
    if len({has_daa_columns(r) for r in episodes}) > 1:
        raise UserError(
            "these campaigns mix episodes with the detect-and-avoid record (episodes.csv with "
            "weight, hmd_m, ...) and episodes without it (a random-traffic campaign written "
            "before it was recorded); merge campaigns of the same scenario flown by the same "
            "version, or fly the older one again."
        )
    if len(goals) > 1:
        what = "; ".join(f"{src}: ({', '.join(map(str, g))})" for g, src in goals.items())
        raise UserError(
            f"these campaigns flew to different goals ({what}), so the same seed is not the same "
            "encounter; a scenario without ownship.goal flies to the service point of its "
            "file's seed (`uavxai evaluate --seed N` keeps it; a campaign written before that, "
            "or run from Python on a scenario whose seed was changed, has another)."
        )
    sources_of: dict[tuple[str, int], set[Path]] = {}
    for (m, n, _), src in flown_by.items():
        sources_of.setdefault((m, n), set()).add(src)
    results = summarise(episodes)
    for r in results:
        if len(sources_of[(r["method"], r["intruders"])]) == 1:
            r["decision_ms_p50"] = p50.get((r["method"], r["intruders"]), r["decision_ms_p50"])

    def write(out: Path, title: str) -> list[dict]:
        with interrupts_deferred():  # a signal now waits for the files: they end whole
            out.mkdir(parents=True, exist_ok=True)
            episode_columns, result_columns = columns_of(episodes)
            write_csv(out / "results.csv", result_columns, results)
            write_csv(out / "episodes.csv", episode_columns, episodes)
            plot_campaign(results, out, title)
        return results

    return write


def _flown_once(r: dict, src: Path, flown_by: dict[tuple[str, int, int], Path]) -> None:
    """Record that ``src`` flew row ``r``'s (method, intruders, seed); the same in two sources
    is an error: it would count twice."""
    key = (r["method"], r["intruders"], r["seed"])
    if (first := _seen_before(flown_by, key, src)) is not None:
        raise UserError(
            f"{key[0]} at {key[1]} intruders, seed {key[2]}: flown in both {first} and "
            f"{src}; merge campaigns of different seeds, methods or intruder counts."
        )


def _seen_before(seen: dict, key: tuple, where: object) -> object | None:
    """Where ``key`` was seen before; None the first time, when it is recorded at ``where``."""
    if key in seen:
        return seen[key]
    seen[key] = where
    return None


def merge_fleet(sources: Sequence[Path]) -> Writer:
    """The writer (:func:`read_merge`) of one fleet campaign from several of the same scenario
    (docs/fleet.md, "Fleet campaigns"): their ``fleet_episodes.csv`` rows pooled,
    ``fleet_results.csv`` and the plots computed again from them by `uavxai evaluate`'s own code
    (:func:`write_fleet_campaign`), so a campaign flown in shards (other seeds, methods or
    intruder counts) merges into the one flown whole. Each method and intruder count's episodes
    are numbered again 0.. in seed order (each source numbers its own from 0), and each
    episode's run folder (``fleet-runs/``) is copied from its source under its new number, where
    the source has it (a campaign flown with ``--ray`` keeps it on the node that flew it).

    Refused: the same (method, intruders, seed) in two sources, an episode numbered twice in
    one, rows of other member counts, a run folder whose summary.json is not its row's (seed,
    planner, intruder count, members) or runs of other scenarios."""
    pooled: list[tuple[dict, Path | None]] = []
    flown_by: dict[tuple[str, int, int], Path] = {}
    members: dict[int, str] = {}
    scenarios: dict[tuple[str, str], Path] = {}
    for src in sources:
        path = src / FLEET_EPISODES
        rows = read_rows(path, FLEET_EPISODE_COLUMNS)
        numbered: dict[tuple[str, int, int], int] = {}
        for i, r in enumerate(rows, start=2):
            r = checked_fleet_row(r, path, i)
            key = (r["method"], r["intruders"], r["episode"])
            if (first := _seen_before(numbered, key, i)) is not None:
                raise UserError(f"{path} line {i}: {key[0]} at {key[1]} intruders, episode "
                                f"{key[2]} again (line {first}); a campaign writes each episode "
                                "once.")  # fmt: skip
            _flown_once(r, src, flown_by)
            members.setdefault(len(r["member_outcomes"].split()), f"{path} line {i}")
            run, summary = _run_of(src, r, path, i)
            if summary is not None:
                scenarios.setdefault((str(summary.get("scenario")),
                                      str(summary.get("dynamics"))), run)  # fmt: skip
            pooled.append((r, run))
    if not pooled:
        raise UserError(f"{', '.join(map(str, sources))}: no episodes in their {FLEET_EPISODES} "
                        "to merge.")  # fmt: skip
    if len(members) > 1:
        what = "; ".join(f"{where}: {n}" for n, where in members.items())
        raise UserError(f"these campaigns flew fleets of different sizes (members: {what}); "
                        "merge campaigns of the same scenario.")  # fmt: skip
    if len(scenarios) > 1:
        what = "; ".join(f"{run}: {scen}, {dyn}" for (scen, dyn), run in scenarios.items())
        raise UserError(f"these campaigns' runs flew different scenarios or dynamics ({what}); "
                        "pooling them would mix missions that are not the same.")  # fmt: skip
    groups: dict[tuple[str, int], list[tuple[dict, Path | None]]] = {}
    for r, run in pooled:
        groups.setdefault((r["method"], r["intruders"]), []).append((r, run))
    episodes, runs = [], []
    for group in groups.values():
        for k, (r, run) in enumerate(sorted(group, key=lambda rr: rr[0]["seed"])):
            episodes.append({**r, "episode": k})
            if run is not None:
                runs.append((run, episode_folder(Path(), r["method"], r["intruders"], k)))

    def write(out: Path, title: str) -> list[dict]:
        out.mkdir(parents=True, exist_ok=True)
        for run, there in runs:
            _copy_run(run, out / there, out)
        with interrupts_deferred():  # a signal now waits for the files: they end whole
            rows, results = write_fleet_campaign(episodes, out)
            plot_fleet(results, rows, out, title)
        return results

    return write


def _run_of(src: Path, r: dict, path: Path, line: int) -> tuple[Path | None, dict | None]:
    """Row ``r``'s run folder in ``src`` and its summary: (None, None) when the source has none
    to copy (flown with --ray, removed, or a link: a link, ``fleet-runs`` itself or the run
    folder, is not followed out of the source). A run folder that is not the row's (its
    summary.json missing, unreadable, or of another seed, planner, intruder count or fleet
    size) is refused, naming both."""
    runs = src / RUNS
    run = episode_folder(src, r["method"], r["intruders"], r["episode"])
    if runs.is_symlink() or not runs.is_dir() or run.is_symlink() or not run.is_dir():
        return None, None
    if not run.resolve().is_relative_to(runs.resolve()):
        return None, None
    file = run / "summary.json"
    try:
        if file.is_symlink() or not file.is_file():
            raise OSError("not a plain file")
        summary = json.loads(file.read_text())
        flown = (summary["seed"], summary["avoidance_planner"],
                 summary["intruders"] - (len(summary["fleet"]) - 1), len(summary["fleet"]))
    except (OSError, UnicodeDecodeError, ValueError, KeyError, TypeError) as exc:
        raise UserError(
            f"{file}: cannot read it as the summary of a fleet run ({exc}); the run folder of "
            f"{path} line {line} must hold the summary.json `uavxai run` wrote (remove {run} "
            "to merge the row without its run files)."
        ) from None
    row = (r["seed"], r["method"], r["intruders"], len(r["member_outcomes"].split()))
    if flown != row:
        show = "seed {}, planner {}, {} intruders, {} members"
        raise UserError(
            f"{file}: a run of {show.format(*flown)}, but its row ({path} line {line}) is "
            f"{show.format(*row)}; the run folder is not that episode's (remove it, or "
            "restore the campaign's own)."
        )
    return run, summary


def _special_files(folder: str, names: list[str]) -> set[str]:
    """What a run folder's copy leaves out: anything but files, folders and links (a FIFO
    would block the copy, a device or socket is no run file)."""
    keep = (stat.S_ISREG, stat.S_ISDIR, stat.S_ISLNK)
    skip = set()
    for name in names:
        try:
            mode = os.lstat(os.path.join(folder, name)).st_mode
        except OSError:
            skip.add(name)
            continue
        if not any(kind(mode) for kind in keep):
            skip.add(name)
    return skip


def _copy_run(run: Path, there: Path, out: Path) -> None:
    """Copy a source's run folder (its files, folders and links as links) to ``there``; a
    failure removes the part copied and is an :class:`OutputError` naming the file (the merged
    folder's marker says it is incomplete)."""

    def full(path: Path, exc: OSError) -> OutputError:  # the disk's message, out's marker
        return OutputError(str(output_error(path, exc)), out)

    def copy(a: str, b: str) -> object:
        try:
            return shutil.copy2(a, b)
        except OSError as exc:  # a full disk keeps its own message (copytree would lose it)
            if exc.errno in NO_SPACE:
                raise full(Path(b), exc) from None
            raise

    if os.path.lexists(there):  # not ours to replace, nor to remove on failure
        raise OutputError(f"cannot copy {run} to {there}: it exists; merge into an empty "
                          "folder.", out)  # fmt: skip
    try:
        shutil.copytree(run, there, symlinks=True, ignore=_special_files, copy_function=copy)
    except OutputError:
        shutil.rmtree(there, ignore_errors=True)
        raise
    except (shutil.Error, OSError) as exc:
        shutil.rmtree(there, ignore_errors=True)
        if isinstance(exc, OSError) and exc.errno in NO_SPACE:
            raise full(there, exc) from None
        failed = exc.args[0][0] if isinstance(exc, shutil.Error) else (exc.filename, "", exc)
        raise OutputError(
            f"cannot copy {failed[0]} into {there} ({failed[2]}); the merged campaign in {out} "
            "is incomplete: make the source's run files readable (or remove that run folder) "
            "and merge again.",
            out,
        ) from None
