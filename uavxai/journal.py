"""A campaign's journal: each finished episode's row, appended the moment it finishes.

``OUT/episodes.journal.jsonl`` opens with one header line naming the campaign (the scenario as
loaded, its seed, the methods, intruder counts, dynamics, goal and the versions that fly it);
every further line is one finished episode's row, written and fsync'ed before the next one is
taken. A campaign killed half-way (SIGKILL, a power cut, a session that ends) then resumes with
``uavxai evaluate ... --resume``: the rows already journaled are read back instead of flown
again. JSON keeps every float to the bit (``repr`` round-trips), so the resumed campaign's
``episodes.csv`` and ``results.csv`` are the ones the uninterrupted campaign writes (the
planner-time columns aside, which no two runs share). A line torn by the kill is not a row:
only whole lines that parse count.

The header must match the campaign being resumed, field by field, or the resume is refused
naming what differs: rows flown on another scenario, seed, dynamics or code would mix
encounters that are not the same. ``episodes`` and ``workers`` may differ: a campaign may grow
(episode i always flies seed + i) and may resume on more or fewer processes.
"""

from __future__ import annotations

import hashlib
import json
import os
from collections.abc import Mapping, Sequence
from pathlib import Path

from uavxai.errors import UserError

JOURNAL = "episodes.journal.jsonl"
FORMAT = 1
# What must be equal for rows to be taken over (everything but the episode count).
_SAME = ("format", "scenario_sha256", "scenario", "seed", "methods", "intruders", "dynamics",
         "goal", "versions")  # fmt: skip

Task = tuple[str, int, int]


def campaign_header(
    scenario,
    methods: Sequence[str],
    intruders: Sequence[int],
    episodes: int,
    dynamics: str,
    goal: Sequence[float],
    versions: Mapping[str, str],
) -> dict:
    """The journal's first line for a campaign (``scenario`` is the loaded Scenario)."""
    dump = scenario.model_dump_json()
    return {
        "format": FORMAT,
        "scenario": scenario.name,
        "scenario_sha256": hashlib.sha256(dump.encode("utf-8")).hexdigest(),
        "seed": int(scenario.seed),
        "methods": list(methods),
        "intruders": [int(n) for n in intruders],
        "episodes": int(episodes),
        "dynamics": dynamics,
        "goal": [float(g) for g in goal],
        "versions": dict(versions),
    }


class Journal:
    """Appends finished rows to ``folder/JOURNAL``; a new journal starts with ``header``."""

    def __init__(self, folder: Path, header: dict) -> None:
        self.path = Path(folder) / JOURNAL
        # O_NOFOLLOW: an output folder's files are never written through a link.
        flags = os.O_WRONLY | os.O_APPEND | os.O_CREAT | os.O_NOFOLLOW
        try:
            # a campaign run from Python (evaluate_command) has no command that made ``folder``
            self.path.parent.mkdir(parents=True, exist_ok=True)
            fd = os.open(self.path, flags, 0o644)
        except OSError as exc:
            raise UserError(f"cannot write the campaign journal {self.path} ({exc}).") from None
        self._file = os.fdopen(fd, "a", encoding="utf-8")
        if self._file.tell() == 0:
            self._write(header)

    def append(self, row: dict) -> None:
        self._write(row)

    def _write(self, record: dict) -> None:
        # One write of one whole line, synced: a kill leaves at most the last line torn.
        self._file.write(json.dumps(record, allow_nan=True, separators=(",", ":")) + "\n")
        self._file.flush()
        os.fsync(self._file.fileno())

    def close(self) -> None:
        self._file.close()


def read_journal(folder: Path, header: dict) -> dict[Task, dict]:
    """The rows journaled in ``folder`` for the campaign ``header`` describes, by task
    (method, intruders, episode); a UserError when there is no journal or it belongs to
    another campaign."""
    path = Path(folder) / JOURNAL
    if path.is_symlink() or not path.is_file():
        raise UserError(
            f"--resume: {folder} holds no campaign journal ({JOURNAL}); a campaign resumes in "
            "the --out folder of the `uavxai evaluate` that was interrupted."
        )
    with open(path, encoding="utf-8") as f:
        lines = f.read().split("\n")
    records = []
    for line in lines[:-1]:  # the part after the last newline is torn or empty
        try:
            records.append(json.loads(line))
        except json.JSONDecodeError:
            raise UserError(f"--resume: {path} is damaged (a line that is not JSON).") from None
    if not records or not isinstance(records[0], dict) or records[0].get("format") != FORMAT:
        raise UserError(f"--resume: {path} does not start with a uavxai campaign header.")
    differ = [k for k in _SAME if records[0].get(k) != header.get(k)]
    if differ:
        said = "; ".join(f"{k}: journal {records[0].get(k)!r}, now {header.get(k)!r}"
                         for k in differ)  # fmt: skip
        raise UserError(
            f"--resume: {folder} journals another campaign ({said}). Resume with the command "
            "that started it (only --episodes, --workers and --ray may change), or choose "
            "another --out."
        )
    wanted = {(m, n) for m in header["methods"] for n in header["intruders"]}
    rows: dict[Task, dict] = {}
    for r in records[1:]:
        task = (r.get("method"), r.get("intruders"), r.get("episode"))
        ok = isinstance(task[2], int) and 0 <= task[2] < header["episodes"]
        if ok and (task[0], task[1]) in wanted:
            rows[task] = r
    return rows
