"""Every family's emulator serves from a thread started inside ``serve()``, so the serving
thread takes the scheduling of the thread that serves (``ffexp emulate --rt`` pins that
thread and asks for SCHED_FIFO: on Linux a new thread takes its creator's policy and CPU
set). A server thread started as the rig opens ran at normal priority on any CPU while
only the idle main thread was real-time (measured on the FR3: its clock lagged 13-35 %)."""

from __future__ import annotations

import os
import threading
from pathlib import Path

import pytest

from drivers.description.scene import load_scene
from drivers.emulate.session import EmulatedRig, EmulatedRigSettings

ROOT = Path(__file__).resolve().parents[1]
#: (emulated controller, scene, the server's own settings)
FAMILIES = [
    ("lwr4", "paper.toml", {"remote": ("127.0.0.45", 49945)}),
    ("ur5e", "paper-ur5e.toml", {"listen": ("127.0.0.45", 0)}),
    ("fr3", "paper-fr3.toml", {"listen": ("127.0.0.45", 0)}),
]


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity here")
@pytest.mark.parametrize(("robot", "scene", "own"), FAMILIES, ids=[f[0] for f in FAMILIES])
def test_the_serving_thread_takes_the_serving_callers_cpu(robot: str, scene: str,
                                                          own: dict[str, object]) -> None:
    cpu = max(os.sched_getaffinity(0))
    settings = EmulatedRigSettings(scene=load_scene(ROOT / "data/scenes" / scene),
                                   robot=robot, host="127.0.0.45", port=0, netft_port=None,
                                   duration_s=5.0, **own)  # type: ignore[arg-type]
    before = {t.ident for t in threading.enumerate()}
    seen: dict[str, set[int]] = {}
    failure: list[BaseException] = []

    def serving_caller() -> None:
        os.sched_setaffinity(0, {cpu})  # this thread only, as ``--rt --cpus`` pins its own

        def stop() -> bool:  # polled while serving: every thread the serve started is here
            for t in threading.enumerate():
                if t.ident not in before and t is not threading.current_thread() and t.native_id:
                    seen[t.name] = os.sched_getaffinity(t.native_id)
            return bool(seen)

        try:
            with EmulatedRig(settings) as rig:
                opened = {t.name for t in threading.enumerate() if t.ident not in before}
                assert opened <= {threading.current_thread().name}, opened
                rig.serve(stop)
        except BaseException as exc:  # re-raised in the test's thread
            failure.append(exc)

    caller = threading.Thread(target=serving_caller, name="serving-caller")
    caller.start()
    caller.join(60.0)
    if failure:
        raise failure[0]
    assert seen, "no serving thread was seen while serving"
    assert all(cpus == {cpu} for cpus in seen.values()), seen
