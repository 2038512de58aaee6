"""The mission in the recording (users, links, rate bars, orbit, service points, phase, tracks,
map): a synthetic mission is written with RunRecorder and read back with rerun's reader."""

from __future__ import annotations

import os
import subprocess
from pathlib import Path

import numpy as np
import pytest
import rerun_cli
import synthetic_mission as sm
from rerun.chunk import RrdReader
from test_recording_recorder import chunks_by_path, column

from uavxai.errors import UserError
from uavxai.recording import entities as ent
from uavxai.recording.mission_log import qos_colors
from uavxai.recording.recorder import RunRecorder


def rgba(packed: int) -> tuple[int, int, int, int]:
    """rerun's Color component is 0xRRGGBBAA."""
    return (packed >> 24) & 255, (packed >> 16) & 255, (packed >> 8) & 255, packed & 255


def ns(t: float) -> int:
    return round(t * 1e9)


@pytest.fixture(scope="module")
def mission(tmp_path_factory):
    path = tmp_path_factory.mktemp("mission") / "mission.rrd"
    samples = sm.mission()
    sm.record(path, samples)
    return path, chunks_by_path(path), samples


def test_mission_entities_are_written(mission):
    _, chunks, samples = mission
    expected = {
        ent.USERS,
        ent.LINKS,
        ent.RATES_AT_QOS,
        ent.RATES_BELOW_QOS,
        ent.RATES_QOS,
        ent.ORBIT,
        ent.SERVICE_POINT,
        ent.SERVICE_POINTS,
        ent.PHASE,
        ent.PHASE_METRIC,
        ent.STATUS,
        ent.MAP_OWNSHIP,
        ent.MAP_INTRUDERS,
        ent.MAP_USERS,
        ent.MAP_ORBIT,
        ent.MAP_SERVICE_POINTS,
        *(f"{ent.TRACKS}/{n}" for n in range(1, len(samples[0].track_ids) + 1)),
    }
    assert {f"/{p}" for p in expected} <= set(chunks)


def test_users_move_and_are_coloured_by_rate_against_qos(mission):
    _, chunks, samples = mission
    times, positions = column(chunks["/world/users"], "Points3D:positions")
    _, colors = column(chunks["/world/users"], "Points3D:colors")
    # the t = 0 row from log_setup, then one per sample
    assert times[1:] == [ns(s.t) for s in samples]
    np.testing.assert_allclose(np.array(positions[-1]), samples[-1].users, atol=1e-3)
    np.testing.assert_allclose(np.array(positions[600]), samples[599].users, atol=1e-3)
    rates = np.array([s.rate_bps for s in samples])
    ok = rates >= sm.QOS_BPS
    # a served user crossing the QoS rate: red side before, green side after
    i, user = next((i, j) for i, j in np.argwhere(~ok[:-1] & ok[1:]) if rates[i, j] > 0)
    before, after = rgba(colors[1 + i][user]), rgba(colors[2 + i][user])
    assert before[0] > 200 and before[1] < 200  # red..orange
    assert after[1] > after[0] and after[1] > 100  # green
    expected = qos_colors(rates[i], sm.QOS_BPS)
    assert [rgba(c) for c in colors[1 + i]] == [tuple(int(v) for v in c) for c in expected]
    # in transit nobody is served: grey (rows 0 and 1 are both at t = 0: setup and sample 0)
    assert set(colors[2]) == {colors[2][0]} and rgba(colors[2][0])[:3] == (140, 140, 140)


def test_moving_things_are_not_static(mission):
    """Static data shadows every timeline in rerun: moving users or a moved service point
    logged static would stand still in the viewer."""
    _, chunks, _ = mission
    for path in ("/world/users", "/world/service_point", "/world/orbit", "/map/users"):
        for chunk in chunks[path]:
            if chunk.is_static:
                names = chunk.to_record_batch().schema.names
                assert not any(n.endswith((":positions", ":strips")) for n in names), path


def test_qos_scale():
    c = qos_colors(np.array([0.0, 0.5e6, 0.99e6, 1e6, 4e6, 9e6]), 1e6)
    assert tuple(c[0, :3]) == (140, 140, 140)  # nothing: grey
    assert c[1, 0] > c[1, 1] and c[2, 0] > c[2, 1]  # below: red side
    assert c[2, 1] > c[1, 1]  # closer to QoS: towards orange
    assert c[3, 1] > c[3, 0] and c[4, 1] > c[4, 0]  # at or above: green side
    assert c[4, 1] < c[3, 1]  # more margin: darker green
    np.testing.assert_array_equal(c[4], c[5])  # saturates at 4x


def test_links_join_the_uav_to_each_served_user(mission):
    _, chunks, samples = mission
    times, strips = column(chunks["/world/links"], "LineStrips3D:strips")
    assert times == [ns(s.t) for s in samples]
    for i in (0, 700, len(samples) - 1):
        s = samples[i]
        served = np.flatnonzero(s.rate_bps > 0)
        assert len(strips[i]) == len(served)
        for strip, j in zip(strips[i], served, strict=True):
            np.testing.assert_allclose(strip[0], s.state.pos[0], atol=1e-2)
            np.testing.assert_allclose(strip[1], s.users[j], atol=1e-2)


def bars(chunks, path: str) -> np.ndarray:
    _, values = column(chunks[path], "BarChart:values")
    return np.array([v[0]["buffer"] for v in values])


def test_rate_bars_split_at_qos(mission):
    _, chunks, samples = mission
    rates = np.array([s.rate_bps for s in samples]) / 1e6
    at, below = bars(chunks, "/service/rates/at_qos"), bars(chunks, "/service/rates/below_qos")
    np.testing.assert_allclose(at + below, rates)
    ok = rates >= sm.QOS_BPS / 1e6
    assert np.all(at[~ok] == 0) and np.all(below[ok] == 0)
    assert ok.any() and (~ok & (rates > 0)).any()  # both colours appear in this mission
    np.testing.assert_allclose(bars(chunks, "/service/rates/qos"), sm.QOS_BPS / 1e6)
    _, x = column(chunks["/service/rates/at_qos"], "BarChart:abscissa")
    assert x[0][0]["buffer"] == list(range(1, len(samples[0].users) + 1))  # bar i = user i


def test_tracks_have_radius_two_sigma_beside_the_truth(mission):
    _, chunks, samples = mission
    decisions = samples[::10]
    times, pos = column(chunks["/world/tracks/2"], "Points3D:positions")
    _, radii = column(chunks["/world/tracks/2"], "Points3D:radii")
    assert times == [ns(s.t) for s in decisions]
    np.testing.assert_allclose([r[0] for r in radii], [2 * s.track_sigma[1] for s in decisions])
    np.testing.assert_allclose([p[0] for p in pos], [s.track_pos[1] for s in decisions], atol=1e-3)
    # the truth stays at world/intruders/2
    assert "/world/intruders/2" in chunks


def test_dropped_track_disappears_and_exact_track_stays_visible(tmp_path):
    path = tmp_path / "tracks.rrd"
    with RunRecorder(path) as rec:
        rec.log_tracks(0.0, ["intruder-1", "a0b1c2"], np.zeros((2, 3)), [0.0, 10.0])
        rec.log_tracks(1.0, ["a0b1c2"], np.ones((1, 3)), [12.0])
    chunks = chunks_by_path(path)
    _, pos = column(chunks["/world/tracks/1"], "Points3D:positions")
    _, radii = column(chunks["/world/tracks/1"], "Points3D:radii")
    assert [len(p) for p in pos] == [1, 0]  # gone at t = 1
    assert radii[0][0] < 0  # sigma 0: a dot in screen units, not a sphere of radius 0
    _, radii = column(chunks["/world/tracks/a0b1c2"], "Points3D:radii")
    assert [r[0] for r in radii] == [20.0, 24.0]


def test_tracks_of_a_planner_picture():
    from uavxai.avoidance.types import Intruder
    from uavxai.recording.mission_log import tracks_of

    picture = [Intruder("intruder-3", 1.0, 2.0, 3.0, 0.0, 0.0, sigma_m=7.5)]
    ids, pos, sigma = tracks_of(picture)
    assert ids == ["intruder-3"] and pos.tolist() == [[1.0, 2.0, 3.0]] and sigma.tolist() == [7.5]
    assert ent.track_path(ids[0]) == "world/tracks/3"  # beside world/intruders/3
    assert tracks_of([])[1].shape == (0, 3)


def test_without_a_file_the_mission_calls_do_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    sm.record(None, sm.mission(duration_s=5.0))
    assert list(tmp_path.iterdir()) == []


def test_map_points_are_the_local_frame_in_wgs84(mission):
    _, chunks, samples = mission
    times, own = column(chunks["/map/ownship"], "GeoPoints:positions")
    assert times == [ns(s.t) for s in samples]
    p = np.array([s.state.pos[0] for s in samples])
    lat, lon, _ = sm.ORIGIN.to_geodetic(p[:, 0], p[:, 1], p[:, 2])
    np.testing.assert_allclose(np.array([o[0] for o in own]), np.column_stack([lat, lon]), 1e-12)
    # about 1 km north-east of the origin is about 0.009 deg of latitude
    assert lat.min() > 47.39 and lat.max() < 47.42
    _, intruders = column(chunks["/map/intruders"], "GeoPoints:positions")
    assert len(intruders[-1]) == len(samples[-1].track_ids)
    _, users = column(chunks["/map/users"], "GeoPoints:positions")
    u = samples[-1].users
    lat, lon, _ = sm.ORIGIN.to_geodetic(u[:, 0], u[:, 1], u[:, 2])
    np.testing.assert_allclose(np.array(users[-1]), np.column_stack([lat, lon]), rtol=1e-12)


def test_phase_changes_once_each_in_log_plot_and_status(mission):
    _, chunks, samples = mission
    changes = [
        s
        for a, s in zip([None, *samples], samples, strict=False)
        if a is None or a.phase != s.phase
    ]
    times, texts = column(chunks["/mission/phase"], "TextLog:text")
    assert times == [ns(s.t) for s in changes]
    assert [t[0] for t in texts] == [
        f"phase: {s.phase.replace('_', ' ')} (synthetic)" for s in changes
    ]
    assert [s.phase for s in changes] == [
        "transit",
        "on_station",
        "avoiding",
        "on_station",
        "returning",
    ]
    times, values = column(chunks["/metrics/phase"], "Scalars:scalars")
    # numbered as in entities.PHASES; the last phase is drawn to the end of the run
    assert [v[0] for v in values] == [0, 1, 2, 1, 3, 3]
    assert times[-1] == ns(samples[-1].t)
    _, status = column(chunks["/mission/status"], "TextDocument:text")
    assert status[-1][0].startswith("**RETURNING**")
    assert "users at QoS" in status[-1][0]


def test_orbit_and_service_point_history(mission):
    _, chunks, samples = mission
    _, strips = column(chunks["/world/orbit"], "LineStrips3D:strips")
    # set on arrival (avoiding keeps the planned orbit), moved once, cleared on returning
    assert [len(s) for s in strips] == [1, 1, 0]
    for row, centre in zip(strips[:2], sm.STATIONS, strict=True):
        circle = np.array(row[0])
        np.testing.assert_allclose(
            np.hypot(*(circle[:, :2] - centre[:2]).T), sm.ORBIT_RADIUS_M, rtol=1e-5
        )
        np.testing.assert_allclose(circle[:, 2], centre[2])
    times, points = column(chunks["/world/service_points"], "Points3D:positions")
    _, labels = column(chunks["/world/service_points"], "Points3D:labels")
    chosen = [s for s in samples if s.service_point is not None]
    assert times == [ns(s.t) for s in chosen] and len(chosen) == 2
    np.testing.assert_allclose(np.array(points[-1]), np.stack(sm.STATIONS), atol=1e-3)
    assert labels[-1] == [f"t = {s.t:.0f} s" for s in chosen]
    _, current = column(chunks["/world/service_point"], "Points3D:positions")
    np.testing.assert_allclose(current[-1][0], sm.STATIONS[1], atol=1e-3)


def test_file_verifies_and_carries_the_blueprint(mission, tmp_path):
    path, *_ = mission
    assert len(RrdReader(path).blueprints()) == 1
    binary = Path(rerun_cli.__file__).parent / "rerun"
    env = {**os.environ, "HOME": str(tmp_path), "XDG_CONFIG_HOME": str(tmp_path)}
    result = subprocess.run(
        [str(binary), "rrd", "verify", str(path)], capture_output=True, text=True, env=env
    )
    assert result.returncode == 0, result.stderr


@pytest.mark.parametrize(
    ("call", "field"),
    [
        (lambda r: r.log_users(0.0, np.zeros((3, 2)), np.zeros(3), 1e6, np.zeros(3)), "users_xyz"),
        (lambda r: r.log_users(0.0, np.zeros((3, 3)), np.zeros(2), 1e6, np.zeros(3)), "rate_bps"),
        (lambda r: r.log_users(0.0, np.zeros((3, 3)), np.zeros(3), -1.0, np.zeros(3)), "qos_bps"),
        (lambda r: r.log_users(0.0, np.zeros((2, 3)), [1.0, np.nan], 1e6, np.zeros(3)), "rate_bps"),
        (lambda r: r.log_users(0.0, np.zeros((3, 3)), np.zeros(3), 1e6, np.zeros(2)), "uav_pos"),
        (lambda r: r.log_tracks(0.0, ["a"], np.zeros((2, 3)), [1.0, 1.0]), "one entry per track"),
        (lambda r: r.log_tracks(0.0, ["a"], np.zeros((1, 3)), [-1.0]), "sigma_m"),
    ],
)
def test_bad_input_names_the_field(tmp_path, call, field):
    with RunRecorder(tmp_path / "bad.rrd") as rec, pytest.raises(UserError, match=field):
        call(rec)


def test_number_of_users_may_change_between_calls(tmp_path):
    path = tmp_path / "k.rrd"
    uav = np.array([0.0, 0.0, 100.0])
    with RunRecorder(path) as rec:
        rec.log_users(0.0, np.ones((3, 3)), [3e6, 0.0, 1e6], 2e6, uav)
        rec.log_users(0.1, np.ones((2, 3)), [1e6, 2e6], 2e6, uav)
    chunks = chunks_by_path(path)
    _, strips = column(chunks["/world/links"], "LineStrips3D:strips")
    assert [len(s) for s in strips] == [2, 2]  # the unserved user gets no link
    np.testing.assert_allclose(bars(chunks, "/service/rates/at_qos"), [[3, 0, 0], [0, 2, 0]])
    np.testing.assert_allclose(bars(chunks, "/service/rates/below_qos"), [[0, 0, 1], [1, 0, 0]])
    _, labels = column(chunks["/world/users"], "Points3D:labels")
    assert labels == [
        ["user 1: 3.0 Mbit/s", "user 2: 0 kbit/s", "user 3: 1.0 Mbit/s"],
        ["user 1: 1.0 Mbit/s", "user 2: 2.0 Mbit/s"],
    ]
