"""The run log's writer thread: the same file as writing in the loop's thread, and its
errors raised in the loop's thread with nothing already recorded lost."""

from __future__ import annotations

import threading
from pathlib import Path

import pytest

from drivers.base.types import RobotState, TargetObservation
from drivers.emulate.lockstep import open_sim
from ffexp import loop
from ffexp.protocol import load_run_protocol, scene_path
from ffexp.recording import Recorder, load
from ffexp.recording.background import Worker
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parents[1]
START_NS = 1_750_000_000 * 10**9


class _Never:
    """A wall clock that never reaches the next flush: the chunks depend on sizes only."""

    def __call__(self) -> float:
        return 0.0


class _FailingSink:
    """A cycle sink that raises in the cycle at ``fail_ns`` of log time (and records
    which thread it ran in)."""

    def __init__(self, fail_ns: int) -> None:
        self.fail_ns = fail_ns
        self.threads: set[str] = set()

    def cycle(self, log_ns: int, state: RobotState, target: TargetObservation | None,
              out: list[tuple[str, bytes]] | None = None) -> None:
        self.threads.add(threading.current_thread().name)
        if log_ns >= self.fail_ns:
            raise ValueError(f"sink failed at {log_ns}")


def _run(path: Path, *, writer_thread: bool, timeout_s: float = 1.0,
         sink: _FailingSink | None = None, chunk_size: int = 1 << 20) -> None:
    ppath = ROOT / "protocols/method1_case1.toml"
    protocol = load_run_protocol(ppath, [f"run.timeout_s={timeout_s}", "run.stop_hold_s=0"])
    robot, sensor = open_sim(scene_path(ppath, protocol), seed=protocol.seed)
    with Recorder(path, clock=_Never(), chunk_size=chunk_size) as rec, RunLog(
            rec, START_NS, protocol.run.tf_period_s, writer_thread=writer_thread) as log:
        if sink is not None:
            log.sinks.append(sink)
        loop.run(protocol, robot, sensor, log)


@pytest.mark.parametrize("chunk_size", [1 << 20, 8 << 10])
def test_the_writer_thread_writes_the_same_file(tmp_path: Path, chunk_size: int) -> None:
    """Byte for byte (messages, log times, order, chunks, indexes, summary), also with
    small chunks, so that chunks are closed (compressed beside the loop) mid-run."""
    serial, threaded = tmp_path / "serial.mcap", tmp_path / "threaded.mcap"
    _run(serial, writer_thread=False, chunk_size=chunk_size)
    _run(threaded, writer_thread=True, chunk_size=chunk_size)
    data = serial.read_bytes()
    assert len(data) > 100_000
    assert threaded.read_bytes() == data


def test_an_error_of_the_writer_is_raised_in_the_loop_and_nothing_is_lost(
        tmp_path: Path) -> None:
    """The same error as without the thread; the file holds what the serial run's holds
    (every cycle before the failing one, no message of it)."""
    fail_ns = START_NS + 150 * 5_000_000
    files = {}
    for writer_thread in (False, True):
        path = files[writer_thread] = tmp_path / f"{writer_thread}.mcap"
        sink = _FailingSink(fail_ns)
        with pytest.raises(ValueError, match=f"sink failed at {fail_ns}"):
            _run(path, writer_thread=writer_thread, sink=sink)
        assert sink.threads == ({"runlog-writer"} if writer_thread
                                else {threading.current_thread().name})
    assert files[True].read_bytes() == files[False].read_bytes()
    rec = load(files[True])
    assert rec.complete
    times = rec.topic("/robot/state").log_time_ns
    assert len(times) == 150 and int(times[-1]) < fail_ns  # the cycles before the failing one
    assert not any(t.name == "runlog-writer" for t in threading.enumerate())


def test_worker_runs_calls_in_order_and_raises_their_error_in_the_caller() -> None:
    worker = Worker("test-worker")
    seen: list[tuple[int, str]] = []

    def call(i: int) -> None:
        seen.append((i, threading.current_thread().name))
        if i == 3:
            raise KeyError("three")

    worker.post(call, (1,))
    worker.post(call, (2,))  # waits for the first
    worker.wait()
    assert seen == [(1, "test-worker"), (2, "test-worker")]
    worker.post(call, (3,))
    with pytest.raises(KeyError, match="three"):
        worker.post(call, (4,))  # the previous call's error, before this one runs
    assert [i for i, _ in seen] == [1, 2, 3]
    worker.post(call, (5,))  # the worker still works after an error
    worker.close()
    worker.close()  # idempotent
    assert [i for i, _ in seen] == [1, 2, 3, 5]
    with pytest.raises(RuntimeError, match="closed"):
        worker.post(call, (6,))


def test_worker_close_raises_the_pending_error_and_ends_the_thread() -> None:
    worker = Worker("test-worker-close")

    def fail() -> None:
        raise OSError("disk full")

    worker.post(fail, ())
    with pytest.raises(OSError, match="disk full"):
        worker.close()
    assert not worker._thread.is_alive()
