"""A real `ray start` head node and `uavxai evaluate --ray auto` against it (slow: Ray's start
and stop take tens of seconds on two cores)."""

from __future__ import annotations

import os
import shutil
import subprocess
import sys
from pathlib import Path

import pytest

pytestmark = pytest.mark.slow


def test_evaluate_on_a_started_ray_head(tmp_path: Path) -> None:
    pytest.importorskip("ray")
    ray_bin = shutil.which("ray") or str(Path(sys.executable).parent / "ray")
    env = {**os.environ, "RAY_USAGE_STATS_ENABLED": "0", "HOME": str(tmp_path)}
    # Ray 2.60 starts heads with token authentication on: the token goes where a user's would
    # (~/.ray/auth_token, here under the test's home), for the head and the driver alike.
    token = subprocess.run(
        [ray_bin, "get-auth-token", "--generate"], env=env, capture_output=True, text=True,
        timeout=120,
    )  # fmt: skip
    assert token.returncode == 0, token.stderr[-2000:]
    start = subprocess.run(
        [ray_bin, "start", "--head", "--num-cpus", "2", "--include-dashboard=false",
         "--disable-usage-stats"],
        env=env, capture_output=True, text=True, timeout=180,
    )  # fmt: skip
    assert start.returncode == 0, start.stderr[-2000:]
    try:
        scenario = tmp_path / "s.yaml"
        scenario.write_text("name: ray\nownship: {goal: [1800, 1800, 120]}\n")
        out = tmp_path / "ev"
        run = subprocess.run(
            [sys.executable, "-m", "uavxai", "evaluate", str(scenario), "--methods", "none",
             "--intruders", "5", "--episodes", "4", "--ray", "auto", "--out", str(out)],
            env=env, capture_output=True, text=True, timeout=600,
        )  # fmt: skip
        assert run.returncode == 0, run.stderr[-3000:]
        assert len((out / "episodes.csv").read_text().splitlines()) == 5
    finally:
        subprocess.run([ray_bin, "stop", "--force"], env=env, capture_output=True, timeout=120)


def test_ray_local_ignores_a_dead_clusters_address_file() -> None:
    """`--ray local` starts its own Ray even where an earlier `ray start` left its address
    behind (Ray's driver would otherwise try to join that cluster and fail)."""
    import tempfile

    pytest.importorskip("ray")
    from uavxai.campaign import run_campaign
    from uavxai.scenario import default_scenario

    # A short folder: Ray's sockets live under it and Unix caps socket paths near 107 bytes.
    ray_tmp = tempfile.mkdtemp(prefix="rt", dir="/tmp")
    (Path(ray_tmp) / "ray").mkdir()
    (Path(ray_tmp) / "ray" / "ray_current_cluster").write_text("192.0.2.2:6379")
    saved = {k: os.environ.get(k) for k in ("RAY_TMPDIR", "RAY_USAGE_STATS_ENABLED")}
    os.environ.update(RAY_TMPDIR=ray_tmp, RAY_USAGE_STATS_ENABLED="0")
    try:
        rows = run_campaign(default_scenario("ray-local"), ["none"], [3], 2, workers=1,
                            ray_address="local")  # fmt: skip
    finally:
        import ray

        ray.shutdown()
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
        shutil.rmtree(ray_tmp, ignore_errors=True)
    assert len(rows) == 2 and {r["method"] for r in rows} == {"none"}
