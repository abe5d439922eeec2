"""A bumpless safe stop and resume, in simulation (the in-process lockstep KRC).

The safe stop ramps from the last command to the hold stiffness and zero wrench
over ``run.stop_ramp_s``: the command moves by a bounded step per cycle (closed
form), and the contact force on the tool changes more slowly than after a one-step
switch. A robot that stops commanding for a few cycles in ALIGN holds the method
(the integral does not grow, the last wrench is repeated) and the method's wrench
is blended in when it commands again: no step in the command.
"""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path

import numpy as np

from drivers.base.types import AppliedCommand, CartesianCommand, RobotState
from drivers.fri.emulate.lockstep import SimRobot, open_sim
from ffexp import loop
from ffexp.contracts import Phase, RunOutcome, StopReason
from ffexp.controllers.force import ForceRi
from ffexp.protocol import load_run_protocol
from ffexp.runlog import RunLog

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols" / "method1_case1.toml"
SCENE = ROOT / "data" / "scenes" / "paper.toml"
CYCLE_S = 0.005
#: In this protocol and scene the tool is in ALIGN (pushing) from 4.67 s to 8.54 s.
STOP_S = 6.0


class Recorded:
    """The sim robot, recording every command and the true contact wrench; it reports
    "not commanding" (and lets the KRC hold) during the ``pause`` cycles."""

    def __init__(self, robot: SimRobot, pause: range = range(0)) -> None:
        self.robot, self.pause, self.k = robot, pause, -1
        self.wrench: list[np.ndarray] = []
        self.stiffness: list[np.ndarray] = []
        self.contact: list[np.ndarray] = []

    def connect(self) -> None:
        self.robot.connect()

    def close(self) -> None:
        self.robot.close()

    def measurements(self) -> Iterator[RobotState]:
        for s in self.robot.measurements():
            self.k += 1
            if self.k in self.pause:
                s.link.commanding = False
            assert s.truth is not None
            self.contact.append(s.truth.contact_wrench[:3].copy())
            yield s

    def send(self, cmd: CartesianCommand | None) -> AppliedCommand:
        assert cmd is not None or self.k < 100
        self.wrench.append(np.zeros(6) if cmd is None else cmd.wrench_n_nm.copy())
        self.stiffness.append(np.zeros(6) if cmd is None else cmd.stiffness_npm_nmprad.copy())
        return self.robot.send(None if self.k in self.pause else cmd)


def simulate(overrides: list[str], pause: range = range(0)
             ) -> tuple[RunOutcome, Recorded, RunLog]:
    protocol = load_run_protocol(PROTOCOL, overrides)
    robot, sensor = open_sim(SCENE, seed=protocol.seed)
    rec = Recorded(robot, pause)
    log = RunLog(None, 0, 0.02)
    out = loop.run(protocol, rec, sensor, log)  # type: ignore[arg-type]
    return out, rec, log


def test_the_safe_stop_ramps_in_and_slows_the_force_transient() -> None:
    ramp_s = 0.1
    common = [f"run.timeout_s={STOP_S}", "run.stop_hold_s=0.3"]
    _out, stepped, _log = simulate([*common, "run.stop_ramp_s=0"])
    out, ramped, _log = simulate([*common, f"run.stop_ramp_s={ramp_s}"])
    assert out.stop_reason is StopReason.TIMEOUT
    protocol = load_run_protocol(PROTOCOL)
    hold_k = np.asarray(protocol.krc.hold_stiffness)
    # the stop's first cycle: where the one-step stop sends the hold stiffness
    k_stop = next(i for i, k in enumerate(stepped.stiffness) if np.array_equal(k, hold_k))
    assert abs(k_stop * CYCLE_S - STOP_S) <= 2 * CYCLE_S
    np.testing.assert_array_equal(stepped.wrench[k_stop], 0.0)
    w, k = np.array(ramped.wrench), np.array(ramped.stiffness)
    np.testing.assert_array_equal(w[:k_stop], np.array(stepped.wrench)[:k_stop])
    w0, k0 = w[k_stop - 1], k[k_stop - 1]
    assert np.abs(w0).max() > 0.5  # the method was pushing when the stop came
    # a straight line to the hold, from the last command: per cycle at most 1/20 of the
    # way (0.1 s at 5 ms), the first step included
    n = round(ramp_s / CYCLE_S)
    steps_w = np.abs(np.diff(w[k_stop - 1:], axis=0))
    steps_k = np.abs(np.diff(k[k_stop - 1:], axis=0))
    assert np.all(steps_w <= np.abs(w0) / n + 1e-12)
    assert np.all(steps_k <= np.abs(hold_k - k0) / n + 1e-9)
    np.testing.assert_allclose(w[k_stop + n:], 0.0, atol=1e-12)
    np.testing.assert_allclose(k[k_stop + n:], np.broadcast_to(hold_k, k[k_stop + n:].shape))

    # the contact force changes more slowly than after switching in one step
    def fastest(r: Recorded) -> float:
        f = np.array(r.contact)[k_stop - 1:]
        return float(np.linalg.norm(np.diff(f, axis=0), axis=1).max())

    assert fastest(ramped) < 0.6 * fastest(stepped)


def test_a_short_pause_in_align_holds_the_method_and_resumes_without_a_step() -> None:
    k_pause, n_pause, ramp_s = round(STOP_S / CYCLE_S), 8, 0.05
    protocol = load_run_protocol(PROTOCOL, [f"run.resume_ramp_s={ramp_s}", "run.timeout_s=7"])
    assert n_pause < protocol.limits.link_lost_cycles  # short of the safety's limit
    robot, sensor = open_sim(SCENE, seed=protocol.seed)
    rec = Recorded(robot, range(k_pause, k_pause + n_pause))
    log = RunLog(None, 0, 0.02)
    integrals: dict[int, np.ndarray] = {}
    cyc: loop.Cycle | None = None
    rec.connect()
    sensor.start()
    try:
        for state in rec.measurements():
            ft = sensor.samples()
            cyc = cyc or loop.Cycle(protocol, state, log)
            intent = cyc.step(state, ft)
            rec.send(intent)
            assert isinstance(cyc.controller, ForceRi)
            integrals[rec.k] = cyc.controller.law.integral
            if rec.k == k_pause + n_pause + 40:
                break
    finally:
        sensor.stop()
        rec.close()
    assert cyc is not None and cyc.task.phase is Phase.ALIGN  # never aborted
    w = np.array(rec.wrench)
    held = w[k_pause - 1]
    # held: the same wrench, and the integral did not grow while nothing was applied
    np.testing.assert_array_equal(w[k_pause:k_pause + n_pause], np.broadcast_to(held, (8, 6)))
    np.testing.assert_array_equal(integrals[k_pause + n_pause - 1], integrals[k_pause - 1])
    # resumed: the first command is the held one, then at most a normal cycle's change
    # plus the blend's share of the gap per cycle
    k_back = k_pause + n_pause
    np.testing.assert_array_equal(w[k_back], held)
    normal = np.abs(np.diff(w[k_pause - 200:k_pause], axis=0)).max(axis=0)
    gap = np.abs(cyc.offset)  # held - the method's wrench at the resume
    blend = gap * CYCLE_S / ramp_s
    after = np.abs(np.diff(w[k_back - 1:], axis=0))
    assert np.all(after <= 2.0 * normal + blend + 1e-12)
    names = [m for _t, name, m in log.events if name == "resume"]
    assert names[0].startswith("robot not commanding in ALIGN")
    assert names[1].startswith(f"robot commanding again after {n_pause} cycles")
