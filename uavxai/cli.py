"""The `uavxai` command line (README "Commands").

Each sub-command parses its flags, loads and validates the scenario, prepares the output folder
and hands over to the module that does the work. Bad input exits 2 with a message and no
traceback; internal errors exit 1 (set UAVXAI_DEBUG=1 to see the traceback).
"""

from __future__ import annotations

import argparse
import contextlib
import errno
import fcntl
import io
import json
import os
import shutil
import stat
import sys
from collections.abc import Sequence
from pathlib import Path
from typing import Any, NoReturn

from uavxai.errors import UserError
from uavxai.outputs import NO_SPACE, OutputError, output_error, write_output
from uavxai.vocabulary import SERVICE_PLANNERS

EXIT_OK, EXIT_INTERNAL, EXIT_BAD_INPUT = 0, 1, 2


class _HelpFormatter(argparse.ArgumentDefaultsHelpFormatter):
    """Every option's help ends with its default, where it has one to show (a default of
    None or False means "not given", which the help text itself explains)."""

    def _get_help_string(self, action: argparse.Action) -> str:
        text = action.help or ""
        if action.default in (None, False, argparse.SUPPRESS) or "%(default)" in text:
            return text
        if action.option_strings or action.nargs in (argparse.OPTIONAL, argparse.ZERO_OR_MORE):
            return f"{text} (default: %(default)s)"
        return text


class _Parser(argparse.ArgumentParser):
    """argparse, but a bad flag is a `UserError` (exit 2, one paragraph, no usage dump), and
    help shows every option's default."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        kwargs.setdefault("formatter_class", _HelpFormatter)
        super().__init__(*args, **kwargs)

    def error(self, message: str) -> NoReturn:
        raise UserError(f"{self.prog}: {message}. See `{self.prog} --help`.")


def _csv_list(kind: type, what: str, allowed: Sequence[str] | None = None):
    def parse(text: str) -> list:
        items = [t.strip() for t in text.split(",") if t.strip()]
        if not items:
            raise argparse.ArgumentTypeError(f"{what}: give a comma-separated list") from None
        out = []
        for item in items:
            try:
                value = kind(item)
            except ValueError:
                raise argparse.ArgumentTypeError(
                    f"{what}: '{item}' is not a {kind.__name__}"
                ) from None
            if allowed is not None and value not in allowed:
                raise argparse.ArgumentTypeError(
                    f"{what}: '{item}' is not one of {', '.join(allowed)}"
                )
            if kind is int and value < 0:
                raise argparse.ArgumentTypeError(f"{what}: '{item}' must be >= 0") from None
            out.append(value)
        return out

    return parse


def _positive_int(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not an integer") from None
    if v < 1:
        raise argparse.ArgumentTypeError(f"'{text}' must be >= 1") from None
    return v


def _seed(text: str) -> int:
    try:
        v = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not an integer seed") from None
    if not 0 <= v < 2**31:
        raise argparse.ArgumentTypeError(f"seed {v} must be in [0, 2^31)") from None
    return v


def _positive_float(text: str) -> float:
    try:
        v = float(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"'{text}' is not a number") from None
    if not v > 0:
        raise argparse.ArgumentTypeError(f"'{text}' must be > 0") from None
    return v


def _mavlink_url(text: str) -> str:
    from uavxai.scenario import check_mavlink_url

    try:
        return check_mavlink_url(text)
    except ValueError as exc:
        raise argparse.ArgumentTypeError(str(exc)) from None


def _dynamics() -> tuple[str, ...]:
    # the names alone (uavxai.vocabulary): building the parser must not import the dynamics,
    # JSBSim and MAVLink, which every command (`explain`, `scenarios`) would wait for
    from uavxai.vocabulary import DYNAMICS_MODELS

    return DYNAMICS_MODELS


def _avoidance_methods() -> tuple[str, ...]:
    from uavxai.vocabulary import avoidance_planners  # the registry's names, checked there

    return avoidance_planners()


_SCENARIO_HELP = "a scenario file, or the name of a shipped one (`uavxai scenarios` lists them)"


def _add_scenario(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("scenario", metavar="SCENARIO.yaml", help=_SCENARIO_HELP)


def _add_force(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--force",
        action="store_true",
        help="overwrite an existing output folder (only one that uavxai made)",
    )


def _add_seed(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--seed", type=_seed, help="override the scenario's seed (default: its own)"
    )


def build_parser() -> argparse.ArgumentParser:
    p = _Parser(
        prog="uavxai",
        description="Interpretable, collision-safe UAV-assisted communication: D3QN service "
        "point, MCTS collision avoidance through ADS-B surveillance, the mission flown in a "
        "JSBSim co-simulation over MAVLink, rerun recordings. Scenario keys: docs/scenario.md.",
        epilog="Exit codes: 0 success, 2 bad input, 1 internal error, 130 interrupted.",
    )
    p.add_argument("--version", action="version", version=f"uavxai {_version()}")
    sub = p.add_subparsers(dest="command", metavar="COMMAND", parser_class=_Parser)
    # One helper per subcommand; the order here is the order `uavxai --help` lists them in.
    _add_run(sub)
    _add_train(sub)
    _add_evaluate(sub)
    _add_merge(sub)
    _add_service(sub)
    _add_explain(sub)
    _add_validate(sub)
    sub.add_parser("scenarios", help="list the shipped scenarios: name, what it flies, file")
    return p


def _add_run(sub: argparse._SubParsersAction) -> None:
    """`uavxai run`: the whole pipeline on a scenario, with its recording and link options."""
    r = sub.add_parser(
        "run",
        help="the co-simulation in JSBSim over MAVLink: service point, then the mission "
        "(transit, on station, home) or the transit-only episode",
    )
    _add_scenario(r)
    r.add_argument("--out", type=Path, help="output folder (default runs/<scenario name>)")
    _add_seed(r)
    r.add_argument(
        "--episodes", type=_positive_int, default=1, help="seeded runs (seed, seed+1, ...)"
    )
    g = r.add_mutually_exclusive_group()
    g.add_argument(
        "--rerun",
        type=Path,
        metavar="FILE.rrd",
        help="write the recording here (default OUT/run.rrd)",
    )
    g.add_argument(
        "--spawn",
        action="store_true",
        help="open the rerun viewer live (the recording file is written too)",
    )
    r.add_argument(
        "--mavlink",
        type=_mavlink_url,
        metavar="URL",
        help="link to ground stations, e.g. udpout:127.0.0.1:14550 (default: the scenario's "
        "bridge.mavlink); they command only if listed in bridge.ground_stations or signed "
        "with bridge.signing_key_hex, and avoidance stays on; every frame goes to OUT/link.tlog",
    )
    r.add_argument(
        "--realtime",
        type=_positive_float,
        metavar="X",
        help="pace simulated time at X times the wall clock (default: flat out)",
    )
    _add_force(r)


# What `uavxai train --stage S` trains: the algorithms of each stage (uavxai.learning).
TRAINABLE = {
    "service": ("d3qn", "dqn"),
    "universal": ("d3qn", "dqn"),
    "avoidance": ("dqn", "safe_dqn"),
}


def _add_train(sub: argparse._SubParsersAction) -> None:
    """`uavxai train`: a learned planner of either stage."""
    t = sub.add_parser("train", help="train a learned planner (progress bar)")
    _add_scenario(t)
    t.add_argument(
        "--stage",
        choices=tuple(TRAINABLE),
        default="service",
        help="which planner to train: service (one layout), universal (the service model for "
        "any layout), avoidance",
    )
    t.add_argument(
        "--algo",
        required=True,
        choices=("d3qn", "dqn", "safe_dqn"),
        help="service, universal: d3qn | dqn; avoidance: dqn | safe_dqn",
    )
    t.add_argument("--episodes", type=_positive_int, help="training episodes (default per algo)")
    t.add_argument(
        "--finetune",
        action="store_true",
        help="service: fine-tune the universal model on this layout instead of training one "
        "from scratch",
    )
    _add_seed(t)
    t.add_argument("--out", type=Path, help="output folder (default runs/train-<stage>-<algo>)")
    _add_force(t)


def _add_evaluate(sub: argparse._SubParsersAction) -> None:
    """`uavxai evaluate`: a Monte Carlo campaign of the avoidance methods."""
    e = sub.add_parser("evaluate", help="Monte Carlo campaign of the avoidance stage")
    _add_scenario(e)
    e.add_argument(
        "--methods",
        required=True,
        metavar="LIST",
        type=_csv_list(str, "--methods", _avoidance_methods()),
        # ", " between names: help wraps at spaces, never inside a method's name
        help=f"comma-separated avoidance methods, any of: {', '.join(_avoidance_methods())}",
    )
    e.add_argument(
        "--intruders",
        metavar="LIST",
        type=_csv_list(int, "--intruders"),
        help="comma-separated intruder counts, e.g. 5,10,20,40 (required, except for a "
        "scenario with `encounters`, which refuses it: each episode flies its encounter's one "
        "intruder)",
    )
    e.add_argument(
        "--episodes",
        type=_positive_int,
        default=100,
        help="episodes per method and intruder count (episode i flies seed + i)",
    )
    e.add_argument(
        "--dynamics",
        choices=_dynamics(),
        default="kinematic",
        help="kinematic: the planner's own model, fast; jsbsim: every aircraft in JSBSim",
    )
    e.add_argument("--workers", type=_positive_int, default=1, help="local worker processes")
    e.add_argument(
        "--ray", metavar="ADDRESS", help="run on a Ray cluster (`auto`, ray://host:port)"
    )
    e.add_argument(
        "--seed",
        type=_seed,
        help="first episode's seed (default: the scenario's); another seed extends a campaign",
    )
    e.add_argument("--out", type=Path, help="output folder (default runs/<scenario name>-evaluate)")
    _add_force(e)
    e.add_argument(
        "--resume",
        action="store_true",
        help="go on with the interrupted campaign in --out (same command, --episodes may "
        "grow): the episodes it journaled are kept, the others flown",
    )


def _add_merge(sub: argparse._SubParsersAction) -> None:
    """`uavxai merge`: campaigns of one scenario pooled into one."""
    m = sub.add_parser(
        "merge",
        help="pool campaign folders of one scenario (other methods, counts or seeds) into one",
    )
    m.add_argument(
        "sources",
        metavar="CAMPAIGN_DIR",
        nargs="+",
        type=Path,
        help="output folders of `uavxai evaluate` (or `uavxai merge`) to pool",
    )
    m.add_argument("--out", type=Path, required=True, help="the merged campaign's folder")
    _add_force(m)


def _add_service(sub: argparse._SubParsersAction) -> None:
    """`uavxai service`: the service-point stage alone."""
    s = sub.add_parser("service", help="the service-point stage alone")
    _add_scenario(s)
    s.add_argument(
        "--planner",
        choices=SERVICE_PLANNERS,
        help="the service-point planner (default: the scenario's service.planner); grid is "
        "the exhaustive reference optimum, slow",
    )
    _add_seed(s)
    s.add_argument("--out", type=Path, help="output folder (default runs/<scenario name>-service)")
    _add_force(s)


def _add_explain(sub: argparse._SubParsersAction) -> None:
    """`uavxai explain`: a run's decisions in words."""
    x = sub.add_parser("explain", help="explain a decision of a run in words")
    x.add_argument(
        "run_dir", metavar="RUN_DIR", type=Path, help="the output folder of `uavxai run`"
    )
    x.add_argument(
        "--decision",
        type=int,
        metavar="N",
        help="decision index (default: all, briefly); negative counts from the end",
    )
    x.add_argument(
        "--member",
        type=int,
        default=0,
        metavar="J",
        help="a fleet's member J (its decisions-J.jsonl; default 0: decisions.jsonl)",
    )


def _add_validate(sub: argparse._SubParsersAction) -> None:
    """`uavxai validate`: check a scenario file."""
    v = sub.add_parser("validate", help="check a scenario file and exit")
    _add_scenario(v)


def _version() -> str:
    from uavxai import __version__

    return __version__


MARKER = ".uavxai-run"  # in every output folder uavxai creates; also its lock file
MARKER_MAX_BYTES = 64_000  # a marker is one short JSON line; a bigger one is not ours
_HELD_LOCKS: dict[Path, Any] = {}  # folder -> its open, locked marker: held until we exit
# folder -> (did this process create the folder, did it create the marker): what to remove
# again when the command refuses before writing anything (see _clean_refused)
_CREATED: dict[Path, tuple[bool, bool]] = {}


def _dangerous(path: Path) -> str | None:
    """Why ``--force`` must never empty ``path`` (None: it may)."""
    resolved = path.resolve()
    cwd, home = Path.cwd().resolve(), Path.home().resolve()
    if resolved == Path(resolved.anchor):
        return "it is the root of the file system"
    if resolved == cwd or resolved in cwd.parents:
        return "it is the current folder or one above it"
    if resolved == home or resolved in home.parents:
        return "it is your home folder or one above it"
    return None


def _marker_kind(path: Path) -> str | None:
    """What is at ``path`` if it is not a plain file (None: nothing, or a plain file)."""
    try:
        st = path.lstat()
    except FileNotFoundError:
        return None
    if stat.S_ISLNK(st.st_mode):
        return "a symbolic link"
    if not stat.S_ISREG(st.st_mode):
        return "not a plain file"
    return None


def _open_marker(path: Path):
    """Open (or create) the marker for reading and writing, never through a link and never a
    FIFO or device (O_NOFOLLOW, O_NONBLOCK, then a check that it is a plain file)."""
    flags = os.O_RDWR | os.O_CREAT | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC
    fd = os.open(path, flags, 0o644)
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            raise OSError(errno.EINVAL, "not a plain file", str(path))
        return os.fdopen(fd, "r+", encoding="utf-8")
    except BaseException:
        os.close(fd)
        raise


def read_marker(folder: Path) -> dict | None:
    """The JSON a folder's marker holds; None if there is none, or it is a link, not a plain
    file, too big or not a JSON object (a marker is never followed or read unbounded)."""
    path = folder / MARKER
    if _marker_kind(path) is not None:
        return None
    try:
        fd = os.open(path, os.O_RDONLY | os.O_NOFOLLOW | os.O_NONBLOCK | os.O_CLOEXEC)
    except OSError:
        return None
    try:
        if not stat.S_ISREG(os.fstat(fd).st_mode):
            return None
        raw = os.read(fd, MARKER_MAX_BYTES + 1)
    except OSError:
        return None
    finally:
        os.close(fd)
    if len(raw) > MARKER_MAX_BYTES:
        return None
    try:
        data = json.loads(raw.decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        return None
    return data if isinstance(data, dict) else None


def _empty_for_force(out: Path, force: bool, had_marker: bool) -> None:
    """Empty ``out`` (all but its marker) if ``--force`` allows it; a folder with other files
    needs ``--force``, and ``--force`` needs the marker (a folder uavxai made). Links are
    removed, never followed."""
    others = [p for p in out.iterdir() if p.name != MARKER]
    if not others:
        return
    if not force:
        raise UserError(
            f"--out {out}: the folder exists and is not empty; choose another folder or "
            "pass --force to overwrite it."
        )
    if not had_marker:
        raise UserError(
            f"--out {out}: refusing --force, this folder was not written by uavxai (it "
            f"has no {MARKER} marker); --force empties only folders uavxai made. Empty "
            "it yourself or choose another --out."
        )
    for p in others:  # the marker stays: it is our lock
        if p.is_dir() and not p.is_symlink():
            shutil.rmtree(p)
        else:
            p.unlink()


def prepare_out_dir(
    out: Path, force: bool, argv: Sequence[str] | None = None, keep: bool = False
) -> Path:
    """Create (or reuse an empty) output folder, mark it as uavxai's and lock it.

    ``keep`` (``evaluate --resume``): the folder must be one uavxai made (it has the marker)
    and its files stay, to be taken over.

    Never overwrites silently: a non-empty folder needs ``--force``, and ``--force`` empties only
    a folder that uavxai made (it holds the ``.uavxai-run`` marker, a plain file), never the
    current folder, home or '/'. Nothing in the folder is followed: a marker that is a symbolic
    link (or a FIFO, a device, a folder) is refused, and ``--force`` removes links, never what
    they point to. The marker file is locked (fcntl) for as long as this process lives, so a
    second run into the same folder fails at once instead of mixing its files into ours. It
    records the command (``argv``, default this process's) that writes the folder.
    """
    argv = sys.argv[1:] if argv is None else argv
    text = str(out)
    if "\x00" in text:
        raise UserError(f"--out {text!r}: a folder name cannot contain a NUL byte.")
    if force and (why := _dangerous(out)):
        raise UserError(f"--out {out}: refusing --force, {why}; choose a folder of its own.")
    try:
        if out.exists() and not out.is_dir():
            raise UserError(f"--out {out}: exists and is not a folder.")
        if kind := _marker_kind(out / MARKER):
            raise UserError(
                f"--out {out}: its {MARKER} is {kind}; uavxai never follows links or writes "
                f"through special files in an output folder. Remove {out / MARKER} or choose "
                "another --out."
            )
        existed = out.is_dir()
        had_marker = (out / MARKER).is_file()
        if keep and not had_marker:
            raise UserError(
                f"--resume: {out} is not the folder of an interrupted `uavxai evaluate` (it "
                f"{'has no ' + MARKER + ' marker' if existed else 'does not exist'}); give the "
                "--out of the campaign to resume."
            )
        out.mkdir(parents=True, exist_ok=True)
        key = out.resolve()
        # a folder this process locked before (main() called twice): release, then lock anew
        old = _HELD_LOCKS.pop(key, None)
        if old is not None:
            old.close()
        lock = _open_marker(out / MARKER)
    except OSError as exc:
        raise UserError(
            f"--out {out}: cannot create or write this folder ({exc.strerror or exc}); choose a "
            "writable folder."
        ) from None
    try:
        fcntl.flock(lock.fileno(), fcntl.LOCK_EX | fcntl.LOCK_NB)
    except OSError:
        lock.close()
        raise UserError(
            f"--out {out}: another uavxai process is writing into this folder right now; wait "
            "for it to end or choose another --out."
        ) from None
    try:
        if not keep:
            _empty_for_force(out, force, had_marker)
        lock.seek(0)
        lock.truncate()
        lock.write(
            json.dumps({"uavxai": _version(), "pid": os.getpid(), "argv": list(argv)}) + "\n"
        )
        lock.flush()
    except BaseException as exc:
        if not had_marker:  # refused a folder that is not ours: leave no marker in it
            (out / MARKER).unlink(missing_ok=True)
        lock.close()
        if isinstance(exc, OSError):
            raise UserError(f"--out {out}: cannot prepare this folder ({exc}).") from None
        raise
    _HELD_LOCKS[key] = lock
    _CREATED[key] = (not existed, not had_marker)
    return out


def _load(args: argparse.Namespace):
    from uavxai.scenario import load_scenario

    scenario = load_scenario(args.scenario)
    if getattr(args, "seed", None) is not None:
        scenario = scenario.with_seed(args.seed)
    return scenario


def _cell(value: Any) -> str | None:
    """A short rendering of one report value (None: leave it out of the table)."""
    if isinstance(value, bool) or value is None:
        return str(value).lower()
    if isinstance(value, int):
        return str(value)
    if isinstance(value, float):
        return f"{value:.6g}"
    if isinstance(value, str):
        return value if len(value) <= 60 else value[:57] + "..."
    if isinstance(value, list | tuple):
        nums = [v for v in value if isinstance(v, int | float) and not isinstance(v, bool)]
        if len(nums) != len(value) or not nums:
            return f"{len(value)} items"
        if len(nums) <= 3:
            return "[" + ", ".join(f"{v:.6g}" for v in nums) + "]"
        return f"{len(nums)} values, {min(nums):.4g} .. {max(nums):.4g}"
    return None


def print_report(title: str, report: dict[str, Any], path: Path, max_rows: int = 24) -> None:
    """A short table of a report's headline values on stdout; the whole report is in ``path``."""
    from rich.console import Console
    from rich.table import Table

    table = Table(title=title, show_header=True, header_style="bold")
    table.add_column("field", no_wrap=True)
    table.add_column("value", overflow="fold")
    rows = []
    for key, value in report.items():
        items = value.items() if isinstance(value, dict) else [(None, value)]
        for sub, v in items:
            cell = _cell(v)
            if cell is not None:
                rows.append((key if sub is None else f"{key}.{sub}", cell))
    for name, cell in rows[:max_rows]:
        table.add_row(name, cell)
    if len(rows) > max_rows:
        table.add_row("...", f"{len(rows) - max_rows} more in {path.name}")
    console = Console(soft_wrap=False, width=max(100, Console().width))
    console.print(table)
    console.print(f"full report: {path}")


def cmd_validate(args: argparse.Namespace) -> int:
    sc = _load(args)
    from uavxai.service.stage import check_planner_fits

    check_planner_fits(sc)
    if sc.fleet.size > 1:  # the homes are checked where the run would check them
        from uavxai.sim.fleet import check_homes

        check_homes(sc)
    print(
        f"{args.scenario}: valid scenario '{sc.name}' (seed {sc.seed}): {sc.comms.users.k} users, "
        f"{sc.intruders.n} intruders, service planner {sc.service.planner}, avoidance planner "
        f"{sc.avoidance.planner}."
    )
    return EXIT_OK


def cmd_service(args: argparse.Namespace) -> int:
    sc = _load(args)
    out = prepare_out_dir(args.out or Path("runs") / f"{sc.name}-service", args.force, args.argv)
    from uavxai.progress import progress_bar
    from uavxai.service.report import service_lines
    from uavxai.service.stage import run_service_stage

    planner = args.planner or sc.service.planner
    with progress_bar() as bar:
        # the exact grid search takes tens of seconds: a bar of the lattice points settled
        task = bar.add_task(f"{planner} search", total=None) if planner == "grid" else None

        def settled(done: int, total: int) -> None:
            bar.update(task, completed=done, total=total)

        summary = run_service_stage(sc, planner, settled if task is not None else None)
    path = write_output(out / "summary.json", json.dumps(summary, indent=2, default=float) + "\n")
    print(f"service point of '{sc.name}'")
    for line in service_lines(summary):
        print(f"  {line}")
    print(f"full report: {path}")
    return EXIT_OK


def cmd_train(args: argparse.Namespace) -> int:
    sc = _load(args)
    allowed = TRAINABLE[args.stage]
    if args.algo not in allowed:
        raise UserError(
            f"--algo {args.algo} is not available for --stage {args.stage}; "
            f"allowed: {', '.join(allowed)}."
        )
    default = Path("runs") / f"train-{args.stage}-{args.algo}"
    out = prepare_out_dir(args.out or default, args.force, args.argv)
    if args.finetune and args.stage != "service":
        raise UserError("--finetune is for --stage service (the universal d3qn/dqn model).")
    if args.stage == "service":
        from uavxai.learning.service import finetune_command, train_command

        trainer = finetune_command if args.finetune else train_command
    elif args.stage == "universal":
        from uavxai.learning.universal import train_command as trainer
    else:
        from uavxai.learning.train import train_command as trainer
    report = trainer(sc, algo=args.algo, episodes=args.episodes, out=out)
    text = json.dumps(report, indent=2, default=float) + "\n"
    path = write_output(out / "train_report.json", text)
    print_report(f"training {args.stage} {args.algo} ({sc.name})", report, path)
    return EXIT_OK


def cmd_evaluate(args: argparse.Namespace) -> int:
    sc = _load(args)
    if sc.encounters is not None and args.intruders is not None:
        raise UserError(
            f"--intruders: scenario '{sc.name}' flies encounters (its `encounters` section): "
            "each episode has its sampled encounter's one intruder; leave --intruders out."
        )
    if sc.encounters is None and args.intruders is None:
        raise UserError("--intruders: give one or more intruder counts, e.g. 5,10,20,40.")
    intruders = [1] if sc.encounters is not None else args.intruders
    if args.resume and args.force:
        raise UserError("--resume keeps the folder's finished episodes and --force would "
                        "empty it: give one of them.")  # fmt: skip
    out = prepare_out_dir(args.out or Path("runs") / f"{sc.name}-evaluate", args.force,
                          args.argv, keep=args.resume)  # fmt: skip
    from uavxai.campaign import evaluate_command
    from uavxai.scenario import load_scenario
    from uavxai.sim.spec import episode_goal

    # the goal of the file's own seed: --seed draws other encounters, not another goal, so a
    # campaign extended with another --seed merges with the first (`uavxai merge`)
    # (a fleet has no goal: each member's station is planned per episode)
    extended = args.seed is not None and sc.fleet.size == 1
    goal = episode_goal(load_scenario(args.scenario)) if extended else None

    evaluate_command(
        sc,
        methods=args.methods,
        intruders=intruders,
        episodes=args.episodes,
        dynamics=args.dynamics,
        workers=args.workers,
        ray_address=args.ray,
        out=out,
        goal=goal,
        resume=args.resume,
    )
    return EXIT_OK


def cmd_merge(args: argparse.Namespace) -> int:
    # --force empties --out before the merge writes: a source in it would be gone unread
    for src in args.sources:
        if src.resolve().is_relative_to(args.out.resolve()):
            what = "is" if src.resolve() == args.out.resolve() else "holds"
            raise UserError(f"--out {args.out}: {what} the source {src}; merge into a folder "
                            "of its own, outside every source.")  # fmt: skip
    _same_campaign(args.sources)
    from rich.console import Console

    from uavxai.campaign import is_fleet_campaign, read_merge, results_table
    from uavxai.campaign.fleet import RUNS, fleet_table
    from uavxai.campaign.plots import FLEET_EPISODES_FIGURE, FLEET_RESULTS_FIGURE

    # every source read and checked before --out is touched: one refused leaves it as it was
    write = read_merge(args.sources)
    out = prepare_out_dir(args.out, args.force, args.argv)
    results = write(out, f"merged from {len(args.sources)} campaigns")
    console = Console(width=None if sys.stdout.isatty() else 200)
    if is_fleet_campaign(out):
        console.print(fleet_table(results))
        episodes = sum(int(r["episodes"]) for r in results)
        runs = sum(1 for p in (out / RUNS).glob("*") if p.is_dir())
        console.print(f"wrote {out / 'fleet_results.csv'}, {out / 'fleet_episodes.csv'}, 2 plots: "
                      f"{out / FLEET_RESULTS_FIGURE}, {out / FLEET_EPISODES_FIGURE}, and the run "
                      f"files of {runs} of the {episodes} episodes in {out / RUNS}/ (copied from "
                      "their sources; a source flown with --ray keeps them on the node that "
                      "flew them)")  # fmt: skip
        return EXIT_OK
    console.print(results_table(results))
    console.print(f"wrote {out / 'results.csv'}, {out / 'episodes.csv'} and the plots")
    return EXIT_OK


def _recorded_command(src: Path) -> argparse.Namespace | None:
    """The command a source folder's marker records (None: the folder has no marker).

    A marker that is a link or not a plain file, unreadable, or records no command that
    `uavxai` would run (``--help``, ``--version``, an unknown flag) is refused: merge must
    not act on it (print help and exit) nor take it on trust."""
    path = src / MARKER
    if not os.path.lexists(path):
        return None
    if kind := _marker_kind(path):
        raise UserError(f"{path}: is {kind}; a campaign folder's marker must be a plain file.")
    data = read_marker(src)
    argv = None if data is None else data.get("argv")
    if not (isinstance(argv, list) and argv and all(isinstance(a, str) for a in argv)):
        raise UserError(
            f"{path}: not a uavxai marker (a short JSON object whose 'argv' lists the command "
            "that wrote the folder); remove it if the folder holds copied results."
        )
    sink = io.StringIO()
    try:
        with contextlib.redirect_stdout(sink), contextlib.redirect_stderr(sink):
            return build_parser().parse_args(argv)
    except (SystemExit, UserError):
        shown = " ".join(argv)
        raise UserError(
            f"{path}: records the command `uavxai {shown[:200]}`, which is not a command that "
            "writes a campaign (merge takes folders written by `uavxai evaluate` or `uavxai "
            "merge`); remove the marker if the folder holds copied results."
        ) from None


def _same_campaign(sources: list[Path]) -> None:
    """Refuse to pool campaigns flown on other scenarios or dynamics, as each folder's marker
    records the `uavxai evaluate` command that wrote it (a folder without one is taken on
    trust: copied results, or a campaign run from Python)."""
    seen: dict[tuple[str, str], Path] = {}
    for src in sources:
        flown = _recorded_command(src)
        if flown is None or flown.command == "merge":
            continue  # its sources were checked when it was made
        if flown.command != "evaluate":
            raise UserError(f"{src}: written by `uavxai {flown.command}`, not by `uavxai "
                            "evaluate`; merge takes campaign folders.")  # fmt: skip
        seen.setdefault((Path(flown.scenario).name, flown.dynamics), src)
    if len(seen) > 1:
        what = "; ".join(f"{src}: {scen}, {dyn}" for (scen, dyn), src in seen.items())
        raise UserError(
            f"these campaigns were flown on different scenarios or dynamics ({what}); pooling "
            "them would mix encounters that are not the same."
        )


def cmd_run(args: argparse.Namespace) -> int:
    sc = _load(args)
    from uavxai.service.stage import check_planner_fits

    check_planner_fits(sc)
    out = prepare_out_dir(args.out or Path("runs") / sc.name, args.force, args.argv)
    from uavxai.sim.run import run_command

    final = run_command(
        sc,
        out=out,
        episodes=args.episodes,
        rerun_file=args.rerun,
        spawn=args.spawn,
        mavlink=args.mavlink,
        realtime=args.realtime,
    )
    if any(e["outcome"] == "interrupted" for e in final.get("episodes", [final])):
        print(
            f"uavxai: interrupted; the files in {out} are whole and summary.json says "
            "outcome 'interrupted'",
            file=sys.stderr,
        )
        return 130
    return EXIT_OK


def cmd_explain(args: argparse.Namespace) -> int:
    from uavxai.xai.explain import explain_command

    print(explain_command(args.run_dir, args.decision, args.member))
    sys.stdout.flush()  # a closed pipe (`| head`) shows here, inside main's handler
    return EXIT_OK


def cmd_scenarios(args: argparse.Namespace) -> int:
    from uavxai.paths import invocation, scenario_catalogue

    rows = scenario_catalogue()
    width = max(len(name) for name, _, _ in rows)
    for name, about, path in rows:
        print(f"{name:<{width}}  {about}")
        print(f"{'':<{width}}  {path}")
    example = "demo" if any(name == "demo" for name, _, _ in rows) else rows[0][0]
    print(f"run one by name: {invocation()} run {example}  (or the path of a copy you edited)")
    return EXIT_OK


COMMANDS = {
    "run": cmd_run,
    "train": cmd_train,
    "evaluate": cmd_evaluate,
    "merge": cmd_merge,
    "service": cmd_service,
    "explain": cmd_explain,
    "validate": cmd_validate,
    "scenarios": cmd_scenarios,
}


def _mark_incomplete(folder: Path | None, reason: str) -> None:
    """Record in an output folder's marker that the command did not finish writing it: the
    marker's JSON gains ``"incomplete": REASON`` (best effort: the disk may be full)."""
    for key, lock in _HELD_LOCKS.items():
        if folder is not None and key != Path(folder).resolve():
            continue
        with contextlib.suppress(OSError, ValueError):
            lock.seek(0)
            data = json.loads(lock.read() or "{}")
            data["incomplete"] = reason[:500]
            lock.seek(0)
            lock.truncate()
            lock.write(json.dumps(data) + "\n")
            lock.flush()


def _clean_refused() -> None:
    """A command that refuses its input removes what it created: an output folder still
    holding nothing but the marker loses the marker (if this process wrote it) and the
    folder (if this process made it)."""
    for key in list(_HELD_LOCKS):
        made_folder, made_marker = _CREATED.get(key, (False, False))
        try:
            if not made_marker or any(p.name != MARKER for p in key.iterdir()):
                continue
            (key / MARKER).unlink(missing_ok=True)
            _HELD_LOCKS.pop(key).close()
            _CREATED.pop(key, None)
            if made_folder:
                key.rmdir()
        except OSError:
            continue


def _internal_error(exc: BaseException) -> int:
    print(
        f"uavxai: internal error: {type(exc).__name__}: {exc}\n"
        "This is a bug in uavxai; rerun with UAVXAI_DEBUG=1 for the traceback and report it.",
        file=sys.stderr,
    )
    return EXIT_INTERNAL


def main(argv: Sequence[str] | None = None) -> int:
    """The program (``argv`` None: ``sys.argv``; given, a caller in Python): its exit code.

    SIGTERM ends a command like Ctrl-C does: files closed whole, a summary marked
    ``interrupted``, finished episodes kept, worker processes stopped; exit code 130. As the
    program, only the first signal does: later ones are ignored, as are signals that come once
    the command is done (the process is ending, its files are whole, and a
    ``KeyboardInterrupt`` raised while it saves or shuts down would cut that short)."""
    from uavxai.processes import ignore_interrupts, raise_on_interrupt, restored_interrupts

    program = argv is None
    # A caller in Python (a test runner) gets its own signal handlers back when the command
    # returns (issue 30: pytest ignored SIGTERM for 15 s after the CLI had run in-process).
    with contextlib.nullcontext() if program else restored_interrupts():
        raise_on_interrupt(once=program)
        try:
            code = _main(argv)
            if program:
                ignore_interrupts()
        except KeyboardInterrupt:  # the first signal, come just as the command ended
            print("uavxai: interrupted", file=sys.stderr)
            code = 130
    return code


def _main(argv: Sequence[str] | None) -> int:
    os.environ.setdefault("JSBSIM_DEBUG", "0")
    os.environ.setdefault("MAVLINK20", "1")
    parser = build_parser()
    try:
        args = parser.parse_args(argv)
        args.argv = list(sys.argv[1:] if argv is None else argv)  # for the output's marker
        if args.command is None:
            parser.print_help()
            return EXIT_BAD_INPUT
        return COMMANDS[args.command](args)
    except UserError as exc:
        if isinstance(exc, OutputError):
            _mark_incomplete(exc.folder, str(exc))
        else:
            _clean_refused()
        print(f"uavxai: error: {exc}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except KeyboardInterrupt:
        print("uavxai: interrupted", file=sys.stderr)
        return 130
    except BrokenPipeError:
        # the reader went away (`uavxai explain RUN | head`): not an error of ours. Point
        # stdout at /dev/null so that the interpreter's final flush does not raise again.
        devnull = os.open(os.devnull, os.O_WRONLY)
        os.dup2(devnull, sys.stdout.fileno())
        os.close(devnull)
        return 141  # 128 + SIGPIPE, what a shell reports for a tool stopped by a closed pipe
    except OSError as exc:
        if os.environ.get("UAVXAI_DEBUG") or exc.errno not in NO_SPACE:
            if os.environ.get("UAVXAI_DEBUG"):
                raise
            return _internal_error(exc)
        # a full disk met by a writer that does not go through write_output (a stream)
        folders = list(_HELD_LOCKS)
        where = folders[-1] if folders else Path(exc.filename or ".").parent
        error = output_error(where / Path(exc.filename or "output").name, exc)
        _mark_incomplete(where if folders else None, str(error))
        print(f"uavxai: error: {error}", file=sys.stderr)
        return EXIT_BAD_INPUT
    except Exception as exc:  # noqa: BLE001 - the last line of defence: no raw traceback
        if os.environ.get("UAVXAI_DEBUG"):
            raise
        return _internal_error(exc)


if __name__ == "__main__":
    sys.exit(main())
