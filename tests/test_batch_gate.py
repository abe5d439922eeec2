"""The physics gate (drivers.world.gate): runs stepped together are the runs alone.

Each run is a chaotic double pendulum of its own (its own model: lengths, damping
and start differ), stepped a different number of cycles, with an input written
before every cycle from its own state, as a controller would. Stepped through the
gate, every run's trajectory must be the trajectory of the run stepped alone, bit
for bit (a chaotic system amplifies any step taken out of turn, with the wrong
input, or twice); one dispatch a cycle steps exactly the runs still going.
"""

from __future__ import annotations

import threading
from collections.abc import Callable

import mujoco
import numpy as np
import pytest

from drivers.world.gate import PhysicsGate, current_gate, use_gate

XML = """
<mujoco>
  <option timestep="0.002" integrator="implicitfast"/>
  <worldbody>
    <body name="a" pos="0 0 1">
      <joint name="j1" type="hinge" axis="0 1 0" damping="{damping}"/>
      <geom type="capsule" fromto="0 0 0 0 0 -{length}" size="0.02" mass="1"/>
      <body name="b" pos="0 0 -{length}">
        <joint name="j2" type="hinge" axis="0 1 0"/>
        <geom type="capsule" fromto="0 0 0 0 0 -0.3" size="0.02" mass="0.5"/>
      </body>
    </body>
  </worldbody>
  <actuator><motor joint="j1"/></actuator>
</mujoco>
"""
SUBSTEPS = 5


def pendulum(k: int) -> tuple[mujoco.MjModel, mujoco.MjData]:
    m = mujoco.MjModel.from_xml_string(XML.format(damping=0.01 * k, length=0.3 + 0.05 * k))
    d = mujoco.MjData(m)
    d.qpos[:] = [1.0 + 0.1 * k, -0.5]
    return m, d


def run(k: int, cycles: int, step: Callable[[mujoco.MjModel, mujoco.MjData, int], None],
        fail_at: int | None = None) -> list[np.ndarray]:
    """Run ``k``: per cycle a feedback input from its state, then the cycle's steps."""
    m, d = pendulum(k)
    out = []
    for c in range(cycles):
        if c == fail_at:
            raise RuntimeError(f"run {k} failed at cycle {c}")
        d.ctrl[0] = -0.5 * d.qvel[0] + 0.1 * np.sin(d.qpos[1])
        step(m, d, SUBSTEPS)
        out.append(np.concatenate([d.qpos, d.qvel, [d.time]]))
    return out


def alone(k: int, cycles: int) -> list[np.ndarray]:
    return run(k, cycles, mujoco.mj_step)


CYCLES = [40, 7, 25, 40, 1, 13]


@pytest.mark.parametrize("threads", [1, 2, 3])
def test_runs_in_a_gate_are_the_runs_alone_bit_for_bit(threads: int) -> None:
    gate = PhysicsGate(threads)
    got: dict[int, list[np.ndarray]] = {}

    def body(k: int) -> None:
        g = current_gate()
        assert g is gate
        got[k] = run(k, CYCLES[k], g.step)

    gate.run([lambda k=k: body(k) for k in range(len(CYCLES))])  # type: ignore[misc]
    for k, n in enumerate(CYCLES):
        ref = alone(k, n)
        assert len(got[k]) == n
        for a, b in zip(got[k], ref, strict=True):
            assert np.array_equal(a, b), (k, a, b)
    # the runs are different runs (a mix-up of models or data would show as equal ones)
    assert not np.array_equal(got[0][-1][:2], got[3][-1][:2])
    # one dispatch a cycle, of exactly the runs still going
    assert gate.stats.dispatches == max(CYCLES)
    expected: dict[int, int] = {}
    for c in range(max(CYCLES)):
        width = sum(n > c for n in CYCLES)
        expected[width] = expected.get(width, 0) + 1
    assert gate.stats.widths == expected
    assert gate.stats.stepped == sum(CYCLES)
    assert not [t for t in threading.enumerate() if t.name.startswith("physics-gate")]


def test_a_run_that_raises_ends_alone_and_the_others_finish() -> None:
    gate = PhysicsGate(2)
    got: dict[int, list[np.ndarray]] = {}
    errors: dict[int, str] = {}

    def body(k: int) -> None:
        try:
            got[k] = run(k, 30, gate.step, fail_at=10 if k == 1 else None)
        except RuntimeError as exc:
            errors[k] = str(exc)

    def dies() -> None:  # an exception the body does not catch ends only that body
        run(4, 30, gate.step, fail_at=5)

    gate.run([lambda k=k: body(k) for k in range(3)] + [dies])  # type: ignore[misc]
    assert errors == {1: "run 1 failed at cycle 10"}
    for k in (0, 2):
        assert all(np.array_equal(a, b) for a, b in zip(got[k], alone(k, 30), strict=True))
    # 4 runs up to cycle 5, then 3 (one died), then 2 after cycle 10
    assert gate.stats.widths == {4: 5, 3: 5, 2: 20}


def test_step_outside_a_batch_steps_alone() -> None:
    gate = PhysicsGate()
    assert current_gate() is None
    with use_gate(gate):
        assert current_gate() is gate
        got = run(2, 6, gate.step)  # not a run of the gate's batch: stepped at once
    assert current_gate() is None
    assert all(np.array_equal(a, b) for a, b in zip(got, alone(2, 6), strict=True))
    assert gate.stats.dispatches == 0


def test_a_gate_runs_one_batch_at_a_time() -> None:
    gate = PhysicsGate()
    seen: list[str] = []

    def nested() -> None:
        try:
            gate.run([])
        except RuntimeError as exc:
            seen.append(str(exc))

    gate.run([nested])
    assert seen == ["this gate is running a batch already"]
    gate.run([])  # and again after the batch
    with pytest.raises(ValueError):
        PhysicsGate(0)


def test_runs_that_join_between_dispatches_are_the_runs_alone() -> None:
    """A refill: a run that ends frees its slot and a queued run joins the lockstep
    before the next dispatch; each run is still the run alone."""
    cycles = [12, 3, 30, 9, 1, 17, 25]
    slots = 3
    queue = list(range(len(cycles)))
    live = {"n": 0}
    got: dict[int, list[np.ndarray]] = {}
    rounds: list[int] = []

    def body(k: int) -> None:
        try:
            got[k] = run(k, cycles[k], gate.step)
        finally:
            live["n"] -= 1

    def take() -> Callable[[], None]:
        k = queue.pop(0)
        live["n"] += 1
        return lambda: body(k)

    def more() -> list[Callable[[], None]]:
        rounds.append(gate.stats.dispatches)
        joining = []
        while queue and live["n"] + len(joining) < slots:
            joining.append(take())
        return joining

    gate = PhysicsGate()
    gate.run([take()], more=more)
    for k, n in enumerate(cycles):
        assert len(got[k]) == n
        assert all(np.array_equal(a, b) for a, b in zip(got[k], alone(k, n), strict=True)), k
    # never more than the slots, every cycle stepped once, and the slots kept full while
    # runs were queued: fewer dispatches than the runs one after the other
    assert max(gate.stats.widths) == slots
    assert gate.stats.stepped == sum(cycles)
    assert gate.stats.dispatches < sum(cycles) / 2
    assert rounds[0] == 0 and rounds[-1] == gate.stats.dispatches  # asked before each round
