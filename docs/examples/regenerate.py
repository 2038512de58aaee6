"""Write the example output quoted in README.md from the commands themselves (issue 29).

README.md marks every generated block::

    <!-- example: NAME -->
    ...generated text...
    <!-- /example -->

and this script runs the commands of each example in a scratch folder (a copy of
`scenarios/`, so the paths read as they do in the repository), keeps their output and writes
it between the marks. Figures that measure the wall clock (decision times, the real-time
factor) differ from run to run and are written as `…`; everything else is a function of the
scenario and its seed, so the same command prints the same block on every run.

    python docs/examples/regenerate.py            # rewrite every block
    python docs/examples/regenerate.py --check    # exit 1 naming each block that differs
    python docs/examples/regenerate.py --check --cheap   # only the blocks CI flies (< 1 min)

`tests/test_docs.py` runs `--check --cheap` in the default suite. The demo mission
takes minutes on two cores, so its blocks are written by this script but not checked in CI.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import shutil
import subprocess
import sys
import tempfile
import textwrap
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

ROOT = Path(__file__).resolve().parents[2]
README = ROOT / "README.md"
WIDTH = 96  # the README's code blocks wrap here
BLOCK = re.compile(r"(<!-- example: (?P<name>[\w-]+) -->\n)(?P<body>.*?)(<!-- /example -->)", re.S)
# Wall-clock figures: the pattern, and what stands in for the number.
WALL_CLOCK = (
    (re.compile(r"decision p50 [\d.]+ ms"), "decision p50 … ms"),
    (re.compile(r"[\d.]+x real time"), "…x real time"),
    (re.compile(r"\((\w+), [\d.]+ ms\)"), r"(\1, … ms)"),
)
# Lines that are progress, not results: the progress bar's last state, stamped with the clock.
PROGRESS = re.compile(r"^\d\d:\d\d:\d\d ")


class Session:
    """A scratch folder in which the examples' commands run, each command once."""

    def __init__(self, folder: Path) -> None:
        self.folder = folder
        shutil.copytree(ROOT / "scenarios", folder / "scenarios")
        self.bin = Path(sys.executable).parent
        self._done: dict[tuple[str, ...], str] = {}

    def uavxai(self, *args: str) -> str:
        """The output of `uavxai ARGS` (stdout and stderr in order), wall-clock figures and
        this machine's paths replaced; an example whose command fails stops the script."""
        if args in self._done:
            return self._done[args]
        exe = self.bin / "uavxai"
        if not exe.exists():
            sys.exit(f"{exe}: no uavxai console script beside this Python; run it from the venv")
        env = {**os.environ, "PYTHONUNBUFFERED": "1", "COLUMNS": "1000", "NO_COLOR": "1"}
        proc = subprocess.run(
            [str(exe), *args],
            cwd=self.folder,
            env=env,
            stdout=subprocess.PIPE,
            stderr=subprocess.STDOUT,
            text=True,
            check=False,
        )
        if proc.returncode != 0:
            sys.exit(f"uavxai {' '.join(args)} exited {proc.returncode}:\n{proc.stdout}")
        self._done[args] = _tidy(proc.stdout, self.bin)
        return self._done[args]

    def summary(self, run_dir: str) -> dict:
        return json.loads((self.folder / run_dir / "summary.json").read_text())

    def decisions(self, run_dir: str) -> list[dict]:
        text = (self.folder / run_dir / "decisions.jsonl").read_text()
        return [json.loads(line) for line in text.splitlines()]


def _tidy(output: str, bindir: Path) -> str:
    lines = []
    for line in output.replace("\r", "\n").splitlines():
        if not line.strip() or PROGRESS.match(line):
            continue
        for pattern, stand_in in WALL_CLOCK:
            line = pattern.sub(stand_in, line)
        lines.append(line.replace(f"{bindir}/", ".venv/bin/"))
    return "\n".join(lines)


def _wrap(text: str) -> str:
    """Wrap long lines as the README does: continuation lines indented past a label
    (`  why:     `, `believed  `) or else four spaces past the line's own indent."""
    out = []
    for line in text.splitlines():
        if len(line) <= WIDTH:
            out.append(line)
            continue
        label = re.match(r"^(\s*(?:[a-z ]+:\s+|[a-z]+\s{2,}))(?=\S)", line)
        indent = " " * (len(label.group(1)) if label else len(line) - len(line.lstrip()) + 4)
        out.extend(textwrap.wrap(line, WIDTH, subsequent_indent=indent, break_on_hyphens=False))
    return "\n".join(out)


def _code(text: str) -> str:
    return f"```text\n{_wrap(text)}\n```\n"


def _shown(s: Session, *cmd: str) -> str:
    """A command as typed, then what it printed."""
    return _code(f"$ uavxai {' '.join(cmd)}\n{s.uavxai(*cmd)}")


DEMO = ("run", "scenarios/demo.yaml", "--out", "runs/demo")
HEAD_ON = ("run", "scenarios/head_on.yaml", "--out", "runs/head_on")


def demo(s: Session) -> str:
    return _shown(s, *DEMO)


def demo_flight(s: Session) -> str:
    """The demo's flight in one sentence, from its summary.json."""
    from uavxai.scenario import load_scenario

    s.uavxai(*DEMO)
    preroll_s = load_scenario(s.folder / "scenarios" / "demo.yaml").surveillance.preroll_s
    e = s.summary("runs/demo")
    m = e["mission"]
    phases = m["phases"]
    manoeuvres = sum(1 for _, phase in m["transitions"] if phase == "avoiding")
    text = (
        f"The demo flies {phases['on_station']:.0f} s of transit, the planner seeing the "
        f"traffic from the start through the receiver's "
        f"{preroll_s:.0f} s pre-roll, then {m['on_station_s']:.0f} s on station, "
        f"{m['avoiding_s']:.0f} s of it avoiding traffic in {manoeuvres} manoeuvres, with "
        f"{len(m['service_points'])} service points as the users walked, and "
        f"{e['flight_time_s'] - phases['returning']:.0f} s home; {e['steps']} decisions in all."
    )
    return textwrap.fill(text, WIDTH) + "\n"


def _named_track(d: dict) -> tuple[dict, dict] | None:
    """The belief and the truth of the intruder a decision's sentence names, if it names one
    the planner tracks."""
    named = re.search(r"from intruder (\d+)", d.get("explanation") or "")
    if named is None:
        return None
    aircraft = f"intruder-{named[1]}"
    belief = [i for i in d["state"]["intruders"] if i["id"] == aircraft]
    truth = [i for i in d["truth"] if i["id"] == aircraft]
    return (belief[0], truth[0]) if belief and truth else None


def demo_belief(s: Session) -> str:
    """Of the demo's decisions whose sentence names an intruder, the one at which that
    intruder's track was furthest from the truth: belief, truth and what was said."""
    s.uavxai(*DEMO)

    def off(pair: tuple[dict, dict]) -> float:
        b, t = pair
        return math.dist((b["x"], b["y"], b["h"]), (t["x"], t["y"], t["h"]))

    named = [(d, pair) for d in s.decisions("runs/demo") if (pair := _named_track(d))]
    d, (b, t) = max(named, key=lambda item: off(item[1]))
    lines = [
        f"decision {d['step']} at t = {d['t']:.0f} s:",
        f"believed  {b['id']} at ({b['x']:.1f}, {b['y']:.1f}, {b['h']:.1f}) m, velocity "
        f"({b['vx']:.1f}, {b['vy']:.1f}) m/s, turning {b['turn_rate']:.3f} rad/s, sigma "
        f"{b['sigma_m']:.1f} m / {b['sigma_v']:.1f} m/s, last report {b['age_s']:.1f} s old",
        f"truth     {t['id']} at ({t['x']:.1f}, {t['y']:.1f}, {t['h']:.1f}) m, velocity "
        f"({t['vx']:.1f}, {t['vy']:.1f}) m/s",
        f'said      "{d["explanation"]}"',
    ]
    words = (
        f"Of the {len(named)} decisions whose sentence names an intruder, this is the one at "
        f"which that intruder's track was furthest from the truth: {off((b, t)):.1f} m off, "
        f"{off((b, t)) / b['sigma_m']:.1f} times the track's stated sigma, "
        f"{abs(b['h'] - t['h']):.1f} m of it in height. `uavxai explain runs/demo --decision "
        f"{d['step']}` prints the whole record."
    )
    return _code("\n".join(lines)) + "\n" + textwrap.fill(words, WIDTH) + "\n"


def head_on(s: Session) -> str:
    return _shown(s, *HEAD_ON)


def explain(s: Session) -> str:
    s.uavxai(*HEAD_ON)
    return _shown(s, "explain", "runs/head_on", "--decision", "3")


def planner_api(s: Session) -> str:
    """The README's library snippet, run as written, and what its last lines evaluate to."""
    text = README.read_text(encoding="utf-8")
    section = text[text.index("## Using the planner in another simulator") :]
    start = section.index("```python\n") + len("```python\n")
    source = section[start : section.index("\n```", start)]
    shown = ("decision.bank_cmd_rad, decision.accel_mps2", "decision.explanation")
    if not all(expr in source for expr in shown):
        sys.exit(f"README.md: the planner snippet no longer reads {' or '.join(shown)}")
    namespace: dict = {}
    exec(compile(source, "README.md", "exec"), namespace)  # the README's own code
    out = []
    for expr in shown:
        out += [f">>> {expr}", repr(eval(expr, namespace))]
    return _code("\n".join(out))


@dataclass(frozen=True)
class Example:
    write: Callable[[Session], str]
    cheap: bool  # under a minute on two cores: checked by the default test suite


EXAMPLES = {
    "demo": Example(demo, cheap=False),
    "demo-flight": Example(demo_flight, cheap=False),
    "demo-belief": Example(demo_belief, cheap=False),
    "head-on": Example(head_on, cheap=True),
    "explain": Example(explain, cheap=True),
    "planner-api": Example(planner_api, cheap=True),
}


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--check", action="store_true", help="change nothing; exit 1 if stale")
    ap.add_argument("--cheap", action="store_true", help="only the blocks CI checks")
    ap.add_argument("names", nargs="*", help=f"examples to write (of {', '.join(EXAMPLES)})")
    args = ap.parse_args(argv)
    unknown = sorted(set(args.names) - set(EXAMPLES))
    if unknown:
        ap.error(f"unknown example(s) {', '.join(unknown)}; allowed: {', '.join(EXAMPLES)}")
    text = README.read_text(encoding="utf-8")
    in_readme = [m["name"] for m in BLOCK.finditer(text)]
    missing = sorted(set(in_readme) - set(EXAMPLES)) + sorted(set(EXAMPLES) - set(in_readme))
    if missing:
        sys.exit(f"README.md and this script disagree on the examples: {', '.join(missing)}")
    wanted = [
        n for n in EXAMPLES
        if (not args.names or n in args.names) and (EXAMPLES[n].cheap or not args.cheap)
    ]  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="uavxai-examples-") as tmp:
        session = Session(Path(tmp))
        fresh = {n: EXAMPLES[n].write(session) for n in wanted}
    text = README.read_text(encoding="utf-8")  # again: the runs take minutes
    stale = []

    def replace(m: re.Match) -> str:
        name = m["name"]
        if name not in fresh or fresh[name] == m["body"]:
            return m.group(0)
        stale.append(name)
        return m.group(1) + fresh[name] + m.group(4)

    new = BLOCK.sub(replace, text)
    if args.check:
        for name in stale:
            print(f"README.md: example block {name!r} differs from what its commands print now;"
                  f" run python docs/examples/regenerate.py {name}", file=sys.stderr)
        return 1 if stale else 0
    if stale:
        README.write_text(new, encoding="utf-8")
    print(f"README.md: {len(wanted)} example(s) run, {len(stale)} rewritten"
          f"{': ' + ', '.join(stale) if stale else ''}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
