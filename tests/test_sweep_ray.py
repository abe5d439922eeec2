"""The Ray executor: ``--executor ray`` starts a Ray instance when none runs and
``ray:auto`` only joins (first, in subprocesses, before this module starts its own);
then against a local Ray instance started by this module (one fixture: Ray's start
costs seconds) the same tiny sweep on Ray and on the process pool gives identical rows
(except wall time), and the MCAP files land in the shared directory."""

from __future__ import annotations

from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path
from typing import Any

import pytest

from ffexp.sweeps import engine, table
from ffexp.sweeps.executors import RayExecutor, make_executor, parse_executor
from ffexp.sweeps.grid import execute, prepare

ray = pytest.importorskip("ray")
ROOT = Path(__file__).resolve().parents[1]
P1 = ROOT / "protocols/method1_case1.toml"

pytestmark = pytest.mark.slow


@pytest.mark.parametrize(("text", "address", "label"), [
    ("ray", "", "ray"), ("ray:auto", "auto", "ray:auto"), ("ray:local", "local", "ray:local"),
    ("ray:10.0.0.5:6379", "10.0.0.5:6379", "ray:10.0.0.5:6379"),
    ("ray://h:10001", "ray://h:10001", "ray:ray://h:10001"),
])
def test_the_ray_executor_texts(text: str, address: str, label: str) -> None:
    spec = parse_executor(text)
    assert (spec.kind, spec.address, spec.label) == ("ray", address, label)


def test_ray_starts_one_here_when_none_runs_and_ray_auto_only_joins() -> None:
    """No cluster (no RAY_ADDRESS, a Ray temp directory of its own, so no ``ray start``
    of this machine is found): ``--executor ray:auto`` is one error line, exit 2, nothing
    run; ``--executor ray`` starts a Ray instance for the sweep (Ray's ``ray.init()``)."""
    import os
    import shutil
    import subprocess
    import sys
    import tempfile

    from ray._private.services import find_gcs_addresses

    home = Path(tempfile.mkdtemp(prefix="ray", dir="/tmp"))  # Ray's socket paths are short
    env = {k: v for k, v in os.environ.items() if k != "RAY_ADDRESS"}
    env.update(RAY_TMPDIR=str(home), PYTHONPATH=str(ROOT))
    sweep = [sys.executable, "-m", "ffexp", "sweep", str(P1), "--vary", "align.k_ri[3]=0.25,0.5",
             "--set", "run.timeout_s=0.4", "--no-figures", "--json"]
    try:
        if find_gcs_addresses():  # ray:auto joins any Ray running on this machine
            pytest.skip("a Ray instance runs on this machine: ray:auto would join it")
        joined = subprocess.run([*sweep, "--executor", "ray:auto", "--out", str(home / "a")],
                                capture_output=True, text=True, env=env, timeout=240)
        assert joined.returncode == 2, joined.stderr
        lines = [x for x in joined.stderr.splitlines() if x.strip()]
        assert len(lines) == 1 and lines[0].startswith("error: --executor: ray:auto: ")
        assert "no running Ray cluster" in lines[0] and not (home / "a" / "runs").exists()
        started = subprocess.run([*sweep, "--executor", "ray", "--out", str(home / "b")],
                                 capture_output=True, text=True, env=env, timeout=240)
        assert started.returncode == 0, started.stderr
        rows = [x for x in started.stdout.splitlines() if x.startswith("{")]
        assert len(rows) == 2
    finally:
        shutil.rmtree(home, ignore_errors=True)


@pytest.fixture(scope="module")
def ray_local() -> Iterator[Any]:
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        yield ray
    finally:
        ray.shutdown()


def _sweep(out: Path, executor: Any, slots: int) -> list[dict[str, Any]]:
    prep = prepare(P1, vary=["align.k_ri[3]=0.25,0.5", "scene.target.lateral=0.010,0.014"],
                   fixed=["run.timeout_s=0.4"])
    with engine.Runner(out, executor, slots) as r:
        rows: list[dict[str, Any]] = execute(prep, r, figures=False)["rows"]
    return rows


def test_ray_and_local_give_identical_rows(ray_local: Any, tmp_path: Path) -> None:
    ex = RayExecutor.connect("auto")  # reuses the instance this process started
    assert ex.slots == 2
    on_ray = _sweep(tmp_path / "ray", ex, ex.slots)
    pool, slots = make_executor(parse_executor("local:2"))
    with pool:
        local = _sweep(tmp_path / "local", pool, slots)
    assert len(on_ray) == 4
    assert table.without_wall_time(on_ray) == table.without_wall_time(local)
    for row in on_ray:
        assert (tmp_path / "ray" / row["path"]).is_file()
    with ThreadPoolExecutor(1) as th:  # and in-process threads agree too
        assert table.without_wall_time(_sweep(tmp_path / "thread", th, 1)) == \
            table.without_wall_time(local)


def test_cli_sweep_on_ray(ray_local: Any, tmp_path: Path) -> None:
    """``--executor ray:auto`` from the command line (the instance of this process)."""
    import json

    from typer.testing import CliRunner

    from ffexp.cli import app

    res = CliRunner().invoke(app, [
        "sweep", str(P1), "--vary", "align.k_ri[3]=0.25,0.5", "--set", "run.timeout_s=0.4",
        "--executor", "ray:auto", "--out", str(tmp_path / "s"), "--json", "--no-figures"])
    assert res.exit_code == 0, res.output
    rows = [json.loads(x) for x in res.stdout.splitlines() if x.startswith("{")]
    assert len(rows) == 2 and all((tmp_path / "s" / r["path"]).is_file() for r in rows)
    assert ray_local.is_initialized()  # a Ray this process started is left running



def test_batches_shipped_to_ray_give_the_rows_of_local(ray_local: Any, tmp_path: Path) -> None:
    """``ray:auto,batch:2``: each Ray task steps a batch of runs together; the rows are
    the pool's, every recording committed."""
    from ffexp.sweeps.batch import BatchExecutor

    spec = parse_executor("ray:auto,batch:2")
    assert (spec.kind, spec.over, spec.batch, spec.label) == ("batch", "ray", 2,
                                                             "ray:auto,batch:2")
    ex, slots = make_executor(spec)
    assert isinstance(ex, BatchExecutor) and slots == 2 * 2  # the fixture's 2 CPUs
    on_ray = _sweep(tmp_path / "ray", ex, slots)
    pool, local_slots = make_executor(parse_executor("local:2"))
    with pool:
        local = _sweep(tmp_path / "local", pool, local_slots)
    assert len(on_ray) == 4
    assert table.without_wall_time(on_ray) == table.without_wall_time(local)
    for row in on_ray:
        assert (tmp_path / "ray" / row["path"]).is_file()
