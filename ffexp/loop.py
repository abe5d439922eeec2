"""The experiment loop: devices in, one cycle of pure parts, devices and the run log out.

Per robot cycle: the F/T samples since the last cycle -> :class:`~ffexp.estimation.Estimator`
-> :class:`~ffexp.safety.SafetyMonitor` -> :class:`~ffexp.task.Task` -> the approach law or
the method's :class:`~ffexp.controllers.Controller` -> a Cartesian impedance command ->
``robot.send`` -> :class:`~ffexp.runlog.RunLog`. :class:`Cycle` is that step alone (no
device, no file: tests and benchmarks call it); :func:`run` clocks it by the robot.
DONE and ABORT end with a safe stop: zero wrench, the hold stiffness, the pose reached,
ramped in from the last command over ``run.stop_ramp_s``. In ALIGN, a robot that stops
commanding for a few cycles (FRI left CMD) holds the method: its controller is not
updated (no integral grows while nothing is applied) and the last wrench is repeated;
when the robot commands again, the method's wrench is blended in from the held one over
``run.resume_ramp_s``, so the command does not step. Both are events.
"""

from __future__ import annotations

import gc
import time
from collections.abc import Callable, Iterator
from contextlib import contextmanager

import numpy as np

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver, TargetTracker
from drivers.base.types import (
    NS_PER_S,
    AppliedCommand,
    CartesianCommand,
    FtSamples,
    RobotState,
    TargetObservation,
)
from drivers.errors import DriverError, DriverTimeoutError, LinkLostError
from ffexp import compiled, controllers, scenarios
from ffexp.contracts import Phase, Progress, RunOutcome, Stop, StopReason
from ffexp.estimation import Estimator
from ffexp.protocol import RunProtocol
from ffexp.runlog import RunLog
from ffexp.safety import SafetyMonitor
from ffexp.task import PhaseChange, Task

#: The phases as module constants: an enum member read through its class costs about
#: 0.3 us in CPython 3.11 (a few of them each cycle), a global a few ns.
_CONNECT, _APPROACH, _ALIGN, _DONE, _ABORT = (
    Phase.CONNECT, Phase.APPROACH, Phase.ALIGN, Phase.DONE, Phase.ABORT)


class Cycle:
    """One cycle of the experiment, from a robot state and F/T samples to a command."""

    def __init__(self, protocol: RunProtocol, first: RobotState, log: RunLog) -> None:
        p = self.p = protocol
        self.t0_ns = first.time_ns
        cycle_s = first.link.cycle_s if first.link.cycle_s > 0 else 0.005
        self.log = log
        self.estimator = Estimator(p.estimation, cycle_s, p.run.tare_s)
        self.safety = SafetyMonitor(p.limits, rows=self.estimator.check_rows())
        self.task = Task(scenarios.build(p), p.run.timeout_s, p.run.stop_hold_s,
                         end_on_aligned=p.run.end_on_aligned)
        self.approach = controllers.Approach(p.approach)
        ctx = controllers.ControlContext(cycle_s, self.approach)
        self.controller = controllers.build_controller(p.align, ctx)
        self.hold_pose = first.tcp_pose_m.copy()
        self.cmd = cmd = CartesianCommand()
        self.total = cmd.wrench_n_nm
        """The wrench sent this cycle (zeros while nothing is sent): the command's own."""
        self.hold_k = np.asarray(p.krc.hold_stiffness, dtype=np.float64)
        self.hold_d = np.asarray(p.krc.hold_damping, dtype=np.float64)
        self.cart_k = np.asarray(p.krc.cart_stiffness, dtype=np.float64)
        self.cart_d = np.asarray(p.krc.cart_damping, dtype=np.float64)
        # the safe stop's ramp: from the last command at the stop's time
        self.stop_ns = 0
        self.from_k, self.from_d, self.from_w = np.zeros(6), np.zeros(6), np.zeros(6)
        # a pause of the robot in ALIGN: cycles held, the blend after it
        self.paused = 0
        self.resume_ns = -1
        self.offset = np.zeros(6)
        # the phase whose pose, stiffness and damping the command holds (written when
        # the phase or the hold pose changes, not every cycle)
        self._written: Phase | None = None
        self._update_estimate = self.estimator.update
        self._task_step = self.task.step
        self._command = self.approach.command
        self._tmp = np.zeros(6)
        # what each cycle's record reads, bound once
        self._log_cycle = log.cycle
        self._out = self.estimator.out
        self._law = self.approach.law
        self.approach_wrench: np.ndarray | None = None
        self.t_ns = 0
        self.target: TargetObservation | None = None
        log.event(0, "INFO", "phase", f"start: {p.name} ({p.method})")
        log.phase(0, PhaseChange(Phase.CONNECT, Phase.CONNECT, "start"), announce=False)

    def stop(self, stop: Stop) -> None:
        """End the run now (unless it has ended) with a safe stop where the tool was last."""
        self.task.end(self.t_ns, stop)
        self.flush_notes()

    def flush_notes(self) -> None:
        """Hand the task's notes of this cycle to the run log, reacting to phase changes."""
        task, t_ns = self.task, self.t_ns
        for note in task.notes:
            self.log.note(t_ns, note)
            if isinstance(note, PhaseChange):
                self._entered(note)
        task.notes.clear()

    def _entered(self, change: PhaseChange) -> None:
        phase = change.new
        s = self.state
        if phase == Phase.APPROACH:
            if change.old == Phase.CONNECT:  # the first approach: the tare pose is home
                self.hold_pose = s.tcp_pose_m.copy()
                self._written = None
                self.safety.set_origin(s.tcp_pose_m)
            if change.old == Phase.CONNECT or not self.controller.continues_approach:
                self.approach.start(self.t_ns, s.tcp_pose_m)  # a new line from here
        elif phase == Phase.ALIGN:
            self.controller.enter(self.t_ns, s, self.estimator.out)
            self.paused, self.resume_ns = 0, -1
            # should the robot pause, the command keeps the wrench sent last (held)
        elif phase.ended:
            self.hold_pose = s.tcp_pose_m.copy()
            self._written = None
            self.stop_ns = self.t_ns
            cmd = self.cmd
            if change.old == Phase.CONNECT:  # nothing was commanded yet: hold at once
                self.from_k[:], self.from_d[:] = self.hold_k, self.hold_d
            else:  # what the last cycle sent
                self.from_k[:], self.from_d[:] = cmd.stiffness_npm_nmprad, cmd.damping_ratio
            self.from_w[:] = self.total

    @staticmethod
    def _fraction(elapsed_ns: int, ramp_s: float) -> float:
        """How far into a ramp of ``ramp_s`` (0 at its start, 1 at and after its end)."""
        if ramp_s <= 0.0:
            return 1.0
        return min(1.0, max(0.0, elapsed_ns / (ramp_s * NS_PER_S)))

    def _blend(self, a: float, start: np.ndarray, end: np.ndarray, out: np.ndarray) -> None:
        """``out = start + a (end - start)`` without allocating."""
        tmp = self._tmp
        np.subtract(end, start, out=tmp)
        tmp *= a
        np.add(start, tmp, out=out)

    def _safe_stop(self, t_ns: int, cmd: CartesianCommand) -> None:
        a = self._fraction(t_ns - self.stop_ns, self.p.run.stop_ramp_s)
        self._blend(a, self.from_k, self.hold_k, cmd.stiffness_npm_nmprad)
        self._blend(a, self.from_d, self.hold_d, cmd.damping_ratio)
        np.multiply(self.from_w, 1.0 - a, out=cmd.wrench_n_nm)

    def _align(self, t_ns: int, state: RobotState, cmd: CartesianCommand) -> None:
        """The method's wrench, held while the robot is not commanding, blended in after.
        In ALIGN the command's wrench is always the one sent last: held, it stays."""
        if not state.link.commanding:
            if self.paused == 0:
                self.log.event(t_ns, "WARNING", "resume",
                               "robot not commanding in ALIGN: the method is held at its last "
                               "command")
            self.paused += 1
            return
        w = self.controller.update(t_ns, state, self.estimator.out)
        if self.paused:
            self.offset[:] = cmd.wrench_n_nm - w  # the held command minus the method's
            self.resume_ns = t_ns
            self.log.event(t_ns, "INFO", "resume",
                           f"robot commanding again after {self.paused} cycles: the method "
                           f"resumes, blended in from the held command over "
                           f"{self.p.run.resume_ramp_s:g} s")
            self.paused = 0
        if self.resume_ns >= 0:
            a = self._fraction(t_ns - self.resume_ns, self.p.run.resume_ramp_s)
            if a >= 1.0:
                self.resume_ns = -1
            np.multiply(self.offset, 1.0 - a, out=self._tmp)
            np.add(w, self._tmp, out=cmd.wrench_n_nm)
        else:
            cmd.wrench_n_nm[...] = w

    def step(self, state: RobotState, ft: FtSamples,
             target: TargetObservation | None = None) -> CartesianCommand | None:
        """Estimate, check, advance the task and command; ``None``: keep the robot's set-point.

        ``target`` is the tracker's newest observation of the target, if the rig has one.
        """
        self.state = state
        self.target = target
        t0_ns = self.t0_ns
        t_ns = self.t_ns = state.time_ns - t0_ns
        task = self.task
        # the estimate and the safety checks on it, one compiled call
        safety = self.safety
        est = self._update_estimate(state, ft, t_ns, t0_ns, safety, task.phase)
        code = self.estimator.safety_code
        if code:
            stop = safety.stop_for(code, t_ns, state, est)
            if stop is not None:
                task.end(t_ns, stop)
        self._task_step(t_ns, state, est, target)
        if task.notes:
            self.flush_notes()
        phase, cmd = task.phase, self.cmd
        self.approach_wrench = None
        if phase is _CONNECT:
            cmd.wrench_n_nm[...] = 0.0  # self.total
            return None
        if phase is not self._written:
            cmd.pose_m[...] = self.hold_pose
            if phase is _APPROACH or phase is _ALIGN:
                cmd.stiffness_npm_nmprad[...] = self.cart_k
                cmd.damping_ratio[...] = self.cart_d
            self._written = phase
        if phase is _APPROACH:  # the law's wrench is the command's (recorded as both)
            self.approach_wrench = self._command(t_ns, state.tcp_pose_m, est.twist_tcf,
                                                 cmd.wrench_n_nm)
        elif phase is _ALIGN:
            self._align(t_ns, state, cmd)
        else:  # DONE, ABORT
            self._safe_stop(t_ns, cmd)
        return cmd

    def record(self, state: RobotState, ft: FtSamples, intent: CartesianCommand | None,
               applied: AppliedCommand) -> None:
        task = self.task
        self._log_cycle(self.t_ns, self.t0_ns, state, ft, self._out, task.phase,
                        self.controller, self.approach_wrench, self._law.setpoint, self.total,
                        intent, applied, self.target, task.scenario if task.observed else None)


#: Where a cycle's wall time goes (``timings`` of :func:`run`): waiting for the robot
#: (in-process: physics), reading the sensor, the pure step, sending, recording.
_PARTS = ("driver", "sensor", "step", "send", "recording")
#: The topic of every F/T sample (:meth:`RunLog.samples <ffexp.runlog.RunLog.samples>`).
FT_TOPIC = "/ft/raw"


def _driver_stop(exc: DriverError) -> Stop:
    if isinstance(exc, LinkLostError):
        return Stop(StopReason.LINK_LOST, f"link lost: {exc}")
    if isinstance(exc, DriverTimeoutError):
        return Stop(StopReason.ROBOT_TIMEOUT, f"robot timed out: {exc}")
    return Stop(StopReason.DRIVER_ERROR, f"device error: {exc}")


def _split_samples(ft: FtSamples, time_ns: int) -> tuple[FtSamples, FtSamples] | None:
    """``ft`` split at ``time_ns`` (up to it, after it); None when none is after it."""
    times = ft.time_ns
    if not times.size or times[-1] <= time_ns:
        return None
    k = int(np.searchsorted(ft.time_ns, time_ns, side="right"))
    return (FtSamples(ft.time_ns[:k], ft.seq[:k], ft.wrench[:k], ft.status[:k]),
            FtSamples(ft.time_ns[k:], ft.seq[k:], ft.wrench[k:], ft.status[k:]))


def _no_measurement(log: RunLog, message: str) -> RunOutcome:
    """The outcome of a run whose robot never sent a state: an ABORT, said in the log."""
    log.event(0, "ERROR", "link", message)
    log.phase(0, PhaseChange(Phase.CONNECT, Phase.ABORT, message, StopReason.NO_MEASUREMENT))
    return RunOutcome(Phase.ABORT, False, StopReason.NO_MEASUREMENT, message, 0, 0.0, 0, 0,
                      log.events)


@contextmanager
def frozen_heap() -> Iterator[None]:
    """While the block runs, the garbage collector leaves alone the objects that exist
    when it starts (``gc.freeze``; unfrozen after it): a full collection in a run then
    walks only what the run made, not the ~100k objects of the model, the scene and the
    modules (one such collection cost 50 to 90 ms in a 30 s run). Nothing is frozen
    when something else has frozen objects (a caller's own ``gc.freeze``)."""
    if gc.get_freeze_count():
        yield
        return
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


def run(protocol: RunProtocol, robot: RobotDriver, sensor: ForceTorqueSensor, log: RunLog, *,
        tracker: TargetTracker | None = None,
        progress: Callable[[Progress], None] | None = None,
        stop_requested: Callable[[], bool] = lambda: False,
        timings: dict[str, float] | None = None) -> RunOutcome:
    """Connect, loop until DONE/ABORT plus the safe-stop hold, close (even on error).

    ``tracker`` (optional) is read once per cycle without blocking. A robot that
    never sends a state (the driver's connect timeout, a link lost or refused before
    the first state, or its end of measurements) is an ABORT with
    :attr:`StopReason.NO_MEASUREMENT` and the driver's message.
    The heap that exists at the start is frozen for the run (:func:`frozen_heap`).
    """
    with frozen_heap():
        return _run(protocol, robot, sensor, log, tracker=tracker, progress=progress,
                    stop_requested=stop_requested, timings=timings)


def _run(protocol: RunProtocol, robot: RobotDriver, sensor: ForceTorqueSensor, log: RunLog, *,
         tracker: TargetTracker | None, progress: Callable[[Progress], None] | None,
         stop_requested: Callable[[], bool], timings: dict[str, float] | None) -> RunOutcome:
    tm = timings if timings is not None else {}
    for key in _PARTS:
        tm.setdefault(key, 0.0)
    # the parts' sums as locals (added to ``tm`` at the end: once, not per cycle)
    t_driver = t_sensor = t_step = t_send = t_recording = 0.0
    clock = time.perf_counter
    timed = timings is not None  # the parts' clocks read only when asked for
    t_a = t_b = t_c = t_c2 = t_d = t_e = 0.0
    cycles, cyc, next_progress_ns = 0, None, 0
    ahead: FtSamples | None = None
    no_state = ""
    # the F/T samples go through the log only when it records them (a lean log does not)
    log_samples = log.samples if log.rec is not None and log.keeps(FT_TOPIC) else None
    compiled.load_kernels()  # every kernel compiled or loaded now: none in the loop
    samples, send = sensor.samples, robot.send  # each cycle's calls, bound once
    latest = tracker.latest if tracker is not None else None
    try:
        robot.connect()
        sensor.start()
        if tracker is not None:
            tracker.start()
        if timed:
            t_a = clock()
        for state in robot.measurements():
            if timed:
                t_b = clock()
            ft = samples()
            if timed:
                t_c = clock()
            if log_samples is not None:
                t0_ns = state.time_ns if cyc is None else cyc.t0_ns
                # log-time order: samples up to the cycle's time before its notes and
                # topics (and before the start's notes), any stamped after it (a sensor
                # clock ahead of the robot's) at the next cycle or the end
                to_log = ft if ahead is None else FtSamples.concat([ahead, ft])
                times = to_log.time_ns  # _split_samples' test, inline: none after the cycle?
                if not times.size or times[-1] <= state.time_ns:
                    log_samples(t0_ns, to_log)
                    ahead = None
                else:
                    split = _split_samples(to_log, state.time_ns)
                    assert split is not None
                    log_samples(t0_ns, split[0])
                    ahead = split[1]
            if cyc is None:
                cyc = Cycle(protocol, state, log)
                task = cyc.task
                step, record = cyc.step, cyc.record
            extras = state.extras
            if extras is not None:  # the back-end's notes on its link, as events
                for _robot_ns, level, name, message in extras.take_events():
                    log.event(state.time_ns - cyc.t0_ns, level, name, message)
            cycles += 1
            if stop_requested():
                task.end(state.time_ns - cyc.t0_ns,
                         Stop(StopReason.STOP_REQUESTED, "stop requested (Ctrl-C / SIGTERM)"))
            if timed:
                t_c2 = clock()
                intent = step(state, ft, None if latest is None else latest())
                t_d = clock()
                applied = send(intent)
                t_e = clock()
                record(state, ft, intent, applied)
                t_f = clock()
                t_driver += t_b - t_a
                t_sensor += t_c - t_b
                t_step += t_d - t_c2
                t_send += t_e - t_d
                t_recording += t_f - t_e + t_c2 - t_c
            else:
                intent = step(state, ft, None if latest is None else latest())
                record(state, ft, intent, send(intent))
            t_ns = cyc.t_ns
            if progress is not None and t_ns >= next_progress_ns:
                next_progress_ns = t_ns + NS_PER_S // 10
                progress(Progress(task.phase, t_ns / NS_PER_S, cyc.estimator.out.f_z,
                                  task.contacts, task.breaks))
            if task.end_ns is not None and t_ns >= task.end_ns:  # task.finished(t_ns)
                break
            if t_ns >= task.timeout_ns:
                task.check_timeout(t_ns)
            if task.notes:
                cyc.flush_notes()
            if timed:
                t_a = clock()
    except DriverError as exc:
        if cyc is None:  # a robot that never answered, however its link says so
            if isinstance(exc, (DriverTimeoutError, LinkLostError)):
                no_state = str(exc)
            else:
                raise
        else:
            cyc.stop(_driver_stop(exc))
    except KeyboardInterrupt:
        if cyc is None:
            raise
        cyc.stop(Stop(StopReason.STOP_REQUESTED, "interrupted"))
    finally:
        for key, dt in zip(_PARTS, (t_driver, t_sensor, t_step, t_send, t_recording),
                           strict=True):
            tm[key] += dt
        try:
            if tracker is not None:
                tracker.stop()
        finally:
            try:
                sensor.stop()
            finally:
                robot.close()
    if cyc is None:
        return _no_measurement(log, no_state or "the robot sent no state")
    cyc.stop(Stop(StopReason.ROBOT_STOPPED, "robot stopped sending measurements"))
    if ahead is not None and log_samples is not None:
        log_samples(cyc.t0_ns, ahead)
    task = cyc.task
    assert task.stop is not None
    return RunOutcome(task.phase, task.aligned, task.stop.reason, task.stop.message, cycles,
                      cyc.t_ns / NS_PER_S, task.contacts, task.breaks, log.events)
