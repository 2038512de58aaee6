"""Every output file of two trees of runs (outputs.sh) compared, but for timing fields.

    python compare_outputs.py BASE NEW    # exit 1 if any file differs

JSON and JSON lines: every key but the timing ones (decision_ms, ms, *wall*, *realtime*, pid,
the sources' hash); CSV: every column but those; telemetry logs: every frame's bytes and its
time stamp from the first (the log's start is the wall clock); PNG and the rest: the bytes.
The console logs, the run marker and the rerun recordings are skipped here (the recordings:
compare_rrd.sh).
"""

from __future__ import annotations

import csv
import io
import json
import re
import struct
import sys
from pathlib import Path

TIMING = re.compile(r"(^|_)ms($|_)|wall|realtime|^pid$|decision_ms|uavxai_sources")
SKIPPED = (".log", ".rrd", ".uavxai-run")


def clean(value: object) -> object:
    if isinstance(value, dict):
        return {k: clean(v) for k, v in value.items() if not TIMING.search(k)}
    if isinstance(value, list):
        return [clean(v) for v in value]
    return value


def tlog_frames(path: Path) -> list[tuple[int, bytes]]:
    """(stamp - first stamp in us, frame bytes) of each record of a MAVProxy .tlog."""
    data, i, out, first = path.read_bytes(), 0, [], None
    while i < len(data):
        stamp = struct.unpack(">Q", data[i : i + 8])[0]
        i += 8
        if data[i] == 0xFD:  # MAVLink 2: header 10, checksum 2, signature 13 if flagged
            n = 10 + data[i + 1] + 2 + (13 if data[i + 2] & 1 else 0)
        else:
            n = 6 + data[i + 1] + 2
        first = stamp if first is None else first
        out.append((stamp - first, data[i : i + n]))
        i += n
    return out


def contents(path: Path) -> object:
    if path.suffix == ".json":
        return clean(json.loads(path.read_text()))
    if path.suffix == ".jsonl":
        return [clean(json.loads(line)) for line in path.read_text().splitlines() if line]
    if path.suffix == ".csv":
        rows = csv.DictReader(io.StringIO(path.read_text()))
        return [{k: v for k, v in row.items() if not TIMING.search(k)} for row in rows]
    if path.suffix == ".tlog":
        return tlog_frames(path)
    return path.read_bytes()


def compare(base: Path, new: Path) -> int:
    differ = 0
    for f in sorted(p for p in base.rglob("*") if p.is_file()):
        rel = f.relative_to(base)
        if f.name.endswith(SKIPPED):
            continue
        same = (new / rel).exists() and contents(f) == contents(new / rel)
        differ += not same
        print("same" if same else "DIFF", rel)
    return differ


if __name__ == "__main__":
    sys.exit(1 if compare(Path(sys.argv[1]), Path(sys.argv[2])) else 0)
