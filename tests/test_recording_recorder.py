"""RunRecorder writes a real .rrd; we read it back with rerun's own reader (docs/recording)."""

from __future__ import annotations

import math
import os
import subprocess
from pathlib import Path

import numpy as np
import pyarrow as pa
import pytest
import rerun_cli
from rerun.chunk import RrdReader

from uavxai.recording import entities as ent
from uavxai.recording import synthetic
from uavxai.recording.aircraft_model import attitude_quaternions
from uavxai.recording.recorder import FILE_FLUSH_S, RecorderProcess, RunRecorder

N_INTRUDERS = 3
INTRUDER_IDS = [f"intruder-{i + 1}" for i in range(N_INTRUDERS)]


def record(
    path: Path | None,
    duration_s: float = 4.9,
    decision_every: int = 10,
    seed: int = 0,
    recorder=RunRecorder,
):
    """50 frames at 10 Hz and a decision (with metrics) every second: 5 decisions."""
    states = list(synthetic.traffic(N_INTRUDERS, duration_s, seed=seed))
    decisions, metrics = [], []
    rec = recorder(path, recording_id=f"test-{seed}")
    rec.log_setup(
        bounds=synthetic.BOUNDS,
        users=synthetic.users(4),
        service_point=np.array([1000.0, 1000.0, 120.0]),
        search_path=np.array([[1000.0, 1000.0, 100.0], [1010.0, 1000.0, 110.0]]),
        intruder_ids=INTRUDER_IDS,
        goal=synthetic.GOAL,
    )
    for i, state in enumerate(states):
        rec.log_traffic(state)
        if i % decision_every == 0:
            k = len(decisions)
            d = synthetic.decision(state, k, seed=seed)
            rec.log_decision(k, state.t, d, INTRUDER_IDS)
            m = dict(
                bank_deg=math.degrees(state.att[0, 0]),
                decision_ms=d.ms,
                min_separation_m=state.min_separation(),
                sum_rate_bps=2.0e7,
                airspeed_mps=float(state.airspeed[0]),
            )
            rec.log_metrics(state.t, **m)
            decisions.append((state.t, d))
            metrics.append((state.t, m))
    rec.close()
    return states, decisions, metrics


def chunks_by_path(path: Path) -> dict[str, list]:
    out: dict[str, list] = {}
    for chunk in RrdReader(path).stream().to_chunks():
        out.setdefault(chunk.entity_path, []).append(chunk)
    return out


def column(chunks: list, name: str, index: str = ent.SIM_TIME) -> tuple[list, list]:
    """(index values, column values) of the temporal rows holding ``name``, in index order."""
    keys, values = [], []
    for chunk in chunks:
        batch = chunk.to_record_batch()
        if chunk.is_static or name not in batch.schema.names:
            continue
        idx = batch.column(index)
        if pa.types.is_duration(idx.type):
            idx = idx.cast(pa.int64())
        keys.extend(idx.to_pylist())
        values.extend(batch.column(name).to_pylist())
    order = np.argsort(keys, kind="stable")
    return [keys[i] for i in order], [values[i] for i in order]


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("rec") / "run.rrd"
    states, decisions, metrics = record(path)
    return path, chunks_by_path(path), states, decisions, metrics


def test_spec_entities_are_written(recording):
    _, chunks, *_ = recording
    expected = {
        ent.OWNSHIP,
        ent.OWNSHIP_TRAIL,
        ent.INTRUDER_TRAILS,
        ent.USERS,
        ent.SERVICE_POINT,
        ent.PLAN,
        ent.TREE,
        ent.EXPLANATION,
        ent.BOUNDS,
        ent.GOAL,
        ent.SEARCH_PATH,
        *(f"{ent.INTRUDERS}/{n}" for n in range(1, N_INTRUDERS + 1)),
        *(ent.metric_path(name) for name in ent.METRIC_NAMES),
    }
    assert {f"/{p}" for p in expected} <= set(chunks)


def test_one_row_per_decision_on_the_decision_timeline(recording):
    _, chunks, _, decisions, _ = recording
    for path, name in [("/xai/tree", "GraphNodes:node_ids"), ("/xai/explanation", "TextLog:text")]:
        seq, _ = column(chunks[path], name, index=ent.DECISION)
        assert seq == list(range(len(decisions))) == [0, 1, 2, 3, 4]
    _, texts = column(chunks["/xai/explanation"], "TextLog:text")
    assert [t[0] for t in texts] == [f"#{k}: {d.explanation}" for k, (_, d) in enumerate(decisions)]


def test_tree_is_capped_and_edges_join_shown_nodes(recording):
    _, chunks, *_ = recording
    _, nodes = column(chunks["/xai/tree"], "GraphNodes:node_ids")
    _, edges = column(chunks["/xai/tree"], "GraphEdges:edges")
    _, kinds = column(chunks["/xai/tree"], "GraphEdges:graph_type")
    for ids, pairs, kind in zip(nodes, edges, kinds, strict=True):
        assert 2 <= len(ids) <= 1 + 9 + 2 * 3  # root, its actions, two expanded branches
        assert len(pairs) == len(ids) - 1  # a tree
        assert {p["first"] for p in pairs} | {p["second"] for p in pairs} <= set(ids)
        assert kind == [2]  # GraphType.Directed


def test_metric_rows_and_values(recording):
    _, chunks, _, _, metrics = recording
    for name in ent.METRIC_NAMES:
        times, values = column(chunks[f"/{ent.metric_path(name)}"], "Scalars:scalars")
        assert len(times) == len(metrics) == 5
        assert times == [round(t * 1e9) for t, _ in metrics]
        np.testing.assert_allclose([v[0] for v in values], [m[name] for _, m in metrics])


def test_ownship_pose_per_frame(recording):
    _, chunks, states, _, _ = recording
    times, translation = column(chunks["/world/ownship"], "Transform3D:translation")
    _, quaternion = column(chunks["/world/ownship"], "Transform3D:quaternion")
    assert len(times) == len(states) == 50
    np.testing.assert_allclose(np.array(translation)[:, 0], [s.pos[0] for s in states], atol=1e-3)
    expected = attitude_quaternions(np.array([s.att[0] for s in states]))
    np.testing.assert_allclose(np.array(quaternion)[:, 0], expected, atol=1e-6)
    # Intruder N is row N of the state.
    _, t3 = column(chunks["/world/intruders/3"], "Transform3D:translation")
    np.testing.assert_allclose(np.array(t3)[:, 0], [s.pos[3] for s in states], atol=1e-3)


def test_trails_are_continuous_and_reach_the_last_frame(recording):
    _, chunks, states, _, _ = recording
    _, own = column(chunks["/world/ownship/trail"], "LineStrips3D:strips")
    segments = [np.array(row[0]) for row in own]
    for before, after in zip(segments, segments[1:], strict=False):
        np.testing.assert_allclose(after[0], before[-1])
    np.testing.assert_allclose(segments[-1][-1], states[-1].pos[0], atol=1e-3)
    _, others = column(chunks["/world/intruders/trails"], "LineStrips3D:strips")
    assert all(len(row) == N_INTRUDERS for row in others)
    np.testing.assert_allclose(np.array(others[-1][1])[-1], states[-1].pos[2], atol=1e-3)


def test_plan_is_the_chosen_branch(recording):
    _, chunks, _, decisions, _ = recording
    _, plans = column(chunks["/world/plan"], "LineStrips3D:strips")
    np.testing.assert_allclose(np.array(plans[-1][0]), decisions[-1][1].plan, atol=1e-3)


def test_file_carries_the_default_blueprint(recording):
    path, *_ = recording
    assert len(RrdReader(path).blueprints()) == 1


def test_blueprint_keeps_the_ownship_path_and_the_intruders_recent_trails(recording):
    """Read back from the file: the 3D view shows the ownship's whole trail up to the time
    cursor and only the intruders' last INTRUDER_TRAIL_S (whole histories of persistent
    traffic fill the box with lines)."""
    from uavxai.recording.blueprint import INTRUDER_TRAIL_S

    path, *_ = recording
    reader = RrdReader(path)
    ranges = {}
    for chunk in reader.stream(store=reader.blueprints()[0]).to_chunks():
        batch = chunk.to_record_batch()
        if "VisibleTimeRanges:ranges" in batch.schema.names:
            for rows in batch.column("VisibleTimeRanges:ranges").to_pylist():
                ranges[chunk.entity_path] = {r["timeline"]: r["range"] for r in rows}
    own = next(v for k, v in ranges.items() if k.endswith("/world/ownship/trail/visualizers"))
    other = next(v for k, v in ranges.items() if k.endswith("/world/intruders/trails/visualizers"))
    assert own == {t: {"start": None, "end": 0} for t in (ent.SIM_TIME, ent.DECISION)}
    assert other[ent.SIM_TIME] == {"start": -round(INTRUDER_TRAIL_S * 1e9), "end": 0}
    assert other[ent.DECISION] == {"start": -INTRUDER_TRAIL_S, "end": 0}


def test_rerun_verifies_the_file(recording, tmp_path):
    path, *_ = recording
    binary = Path(rerun_cli.__file__).parent / "rerun"
    # Keep the CLI's first-run analytics notice and config out of the real home folder.
    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path)}
    result = subprocess.run(
        [str(binary), "rrd", "verify", str(path)], capture_output=True, text=True, env=env
    )
    assert result.returncode == 0, result.stderr


def test_long_run_is_flushed_in_pieces_without_losing_frames(tmp_path):
    duration = FILE_FLUSH_S * 2 + 5  # three flushes
    states, _, _ = record(tmp_path / "long.rrd", duration_s=duration)
    chunks = chunks_by_path(tmp_path / "long.rrd")
    times, _ = column(chunks["/world/ownship"], "Transform3D:translation")
    assert times == [round(s.t * 1e9) for s in states]
    _, own = column(chunks["/world/ownship/trail"], "LineStrips3D:strips")
    for before, after in zip(own, own[1:], strict=False):
        np.testing.assert_allclose(after[0][0], before[0][-1])


def test_a_recorder_process_writes_the_same_recording(tmp_path, recording):
    """`uavxai run` records on its own process (RecorderProcess): the same calls give the
    same entities, rows and values as recording in-process."""
    _, here, *_ = recording
    path = tmp_path / "process.rrd"
    record(path, recorder=RecorderProcess)
    there = chunks_by_path(path)
    assert set(there) == set(here)
    for entity in here:
        for chunk in here[entity]:
            if chunk.is_static:
                continue
            for name in chunk.to_record_batch().schema.names:
                if name.startswith("rerun.controls") or ":" not in name:
                    continue  # row ids and the index columns: compared through the values
                assert column(there[entity], name) == column(here[entity], name), (entity, name)


def test_two_recorders_in_one_process_stay_apart(tmp_path):
    a, b = tmp_path / "a.rrd", tmp_path / "b.rrd"
    rec_a, rec_b = RunRecorder(a, recording_id="a"), RunRecorder(b, recording_id="b")
    for t in range(3):
        rec_a.log_metrics(float(t), bank_deg=1.0)
        rec_b.log_metrics(float(t), bank_deg=-1.0)
    rec_b.log_metrics(3.0, bank_deg=-1.0)
    rec_a.close()
    rec_b.close()
    for path, value, rows in [(a, 1.0, 3), (b, -1.0, 4)]:
        (entry,) = RrdReader(path).recordings()
        assert entry.recording_id == path.stem
        _, values = column(chunks_by_path(path)["/metrics/bank_deg"], "Scalars:scalars")
        assert [v[0] for v in values] == [value] * rows


def test_without_a_file_or_viewer_nothing_is_recorded(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    record(None, duration_s=1.0)
    assert list(tmp_path.iterdir()) == []


def test_non_finite_metrics_become_gaps(tmp_path):
    path = tmp_path / "gaps.rrd"
    with RunRecorder(path) as rec:
        rec.log_metrics(0.0, min_separation_m=math.inf)
        rec.log_metrics(0.1, min_separation_m=80.0)
    _, values = column(chunks_by_path(path)["/metrics/min_separation_m"], "Scalars:scalars")
    assert math.isnan(values[0][0]) and values[1][0] == 80.0


def test_log_sample_derives_the_metrics_from_the_sample(tmp_path):
    """One call per sample: the traffic, and the metrics the recorder computes from it: the
    sum rate at the ownship with the run's link (NaN without one), the separation, the bank
    and the airspeed."""
    from uavxai.comms.channel import Channel
    from uavxai.scenario import default_scenario

    users = synthetic.users(4)
    channel = Channel.from_scenario(default_scenario("rec"), users=users)
    power = np.full(4, 0.25)
    states = list(synthetic.traffic(N_INTRUDERS, 1.0, seed=2))
    for link, name in ((channel, power), "link"), (None, "none"):
        rec = RunRecorder(tmp_path / f"{name}.rrd")
        rec.log_setup(synthetic.BOUNDS, users, None, None, INTRUDER_IDS, synthetic.GOAL, link=link)
        for s in states:
            rec.log_sample(s, decision_ms=12.0)
        rec.close()
        chunks = chunks_by_path(tmp_path / f"{name}.rrd")
        _, own = column(chunks["/world/ownship"], "Transform3D:translation")
        assert len(own) == len(states)
        got = {
            m: [v[0] for v in column(chunks[f"/{ent.metric_path(m)}"], "Scalars:scalars")[1]]
            for m in ent.METRIC_NAMES
        }
        rates = [float(channel.sum_rate_bps(s.pos[0], power)) for s in states]
        if link is None:
            assert all(math.isnan(v) for v in got["sum_rate_bps"])
        else:
            np.testing.assert_allclose(got["sum_rate_bps"], rates, rtol=1e-6)
            assert len(set(rates)) > 1  # the ownship moved: the rates are per sample
        np.testing.assert_allclose(got["min_separation_m"], [s.min_separation() for s in states])
        np.testing.assert_allclose(got["bank_deg"], [math.degrees(s.att[0, 0]) for s in states])
        np.testing.assert_allclose(got["airspeed_mps"], [s.airspeed[0] for s in states])
        assert got["decision_ms"] == [12.0] * len(states)
