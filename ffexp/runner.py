"""The experiment: phases, the per-cycle loop, safe stop and abort.

Phases::

    CONNECT  link up, commanding hold while the F/T sensor is tared in free space
    APPROACH external impedance law, set-point moving along the approach line
    ALIGN    on contact: force control (methods I, II) or impedance kept (III)
    DONE     aligned (held for ``alignment.hold_s``) or timed out
    ABORT    a limit, sensor saturation, stale F/T data, lost link, or a stop request

Contact lost during ALIGN returns to APPROACH and counts a break, as the
paper does. DONE and ABORT end with a safe stop: zero superposed wrench,
hold the measured pose on every axis. The loop is the same on every driver:
it is clocked by ``robot.measurements()``.
"""

from __future__ import annotations

import enum
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from drivers.base.interfaces import ForceTorqueSensor, RobotDriver
from drivers.base.types import (
    CmdFlags,
    Command,
    ControlMode,
    FriQuality,
    FriState,
    FtSamples,
    Measurement,
)
from drivers.errors import DriverError
from ffexp.control import ForceController, ForceControlTerms, ImpedanceController
from ffexp.estimation import ContactDetector, ContactEvent, MotionFilter, WrenchFilter
from ffexp.protocol import RunProtocol
from ffexp.recording import Recorder

SATURATION_BIT = 0x00020000
NS = 1_000_000_000


class Phase(enum.IntEnum):
    CONNECT = 0
    APPROACH = 1
    ALIGN = 2
    DONE = 3
    ABORT = 4


@dataclass
class Progress:
    """What the live progress line shows."""

    phase: Phase
    time_s: float
    f_z_n: float
    contacts: int
    breaks: int


@dataclass
class RunOutcome:
    """How a run ended (the numbers come from the recording: ffexp.analysis)."""

    phase: Phase
    aligned: bool
    reason: str
    cycles: int
    duration_s: float
    contacts: int
    breaks: int
    events: list[tuple[float, str, str]] = field(default_factory=list)


class Runner:
    """Runs one protocol on a robot/sensor pair, writing through a Recorder.

    Args:
        protocol: the experiment.
        robot, sensor: connected or not; the runner connects and closes them.
        recorder: where every cycle goes; the caller finishes it.
        start_utc_ns: log-time origin (run start in UTC); cycle times are added.
        progress: called about ten times a second of run time.
        stop_requested: polled every cycle (Ctrl-C / SIGTERM); True -> ABORT.
    """

    def __init__(
        self,
        protocol: RunProtocol,
        robot: RobotDriver,
        sensor: ForceTorqueSensor,
        recorder: Recorder,
        *,
        start_utc_ns: int,
        progress: Callable[[Progress], None] | None = None,
        stop_requested: Callable[[], bool] = lambda: False,
    ) -> None:
        self.p = protocol
        self.robot = robot
        self.sensor = sensor
        self.rec = recorder
        self.start_utc_ns = start_utc_ns
        self.progress = progress
        self.stop_requested = stop_requested
        self.phase = Phase.CONNECT
        self.outcome_reason = ""
        self.aligned = False
        self.contacts = 0
        self.breaks = 0
        self.events: list[tuple[float, str, str]] = []
        self._cmd = Command()
        self._t0_ns: int | None = None
        self._tare: list[np.ndarray] = []
        self._hold_pose = np.eye(4)
        self._last_pose = np.eye(4)
        self._start_pose = np.eye(4)
        self._phase_start_ns = 0
        self._stop_at_ns: int | None = None
        self._aligned_since_ns: int | None = None
        self._first_contact_z: float | None = None
        self._last_ft_ns: int | None = None
        self._bad_link_cycles = 0
        self._next_tf_ns = 0
        self._next_progress_ns = 0
        self._impedance_wrench = np.zeros(6)
        self._zero6 = np.zeros(6)
        self._approach_anchor_ns = 0
        # Method III has no force reference: record zeros, not the unused default
        self._f_ref = np.zeros(6) if protocol.method == "impedance" else np.asarray(
            protocol.align.f_ref, dtype=np.float64
        )
        self.force_terms: ForceControlTerms | None = None
        self._no_terms = ForceControlTerms()  # zeros, for cycles without force control
        #: Wall time spent per part of the loop [s] (for the benchmark; cheap).
        self.timings: dict[str, float] = dict.fromkeys(
            ("driver", "sensor", "estimation", "control", "recording"), 0.0
        )

    # -- helpers --------------------------------------------------------------
    def _log_ns(self, t_ns: int) -> int:
        return self.start_utc_ns + t_ns

    def _event(self, t_ns: int, level: str, name: str, message: str) -> None:
        self.events.append((t_ns / NS, name, message))
        self.rec.log(self._log_ns(t_ns), level, name, message)

    def _set_phase(self, t_ns: int, phase: Phase, reason: str) -> None:
        if phase == self.phase:
            return
        old = self.phase
        self.phase = phase
        self._phase_start_ns = t_ns
        self.rec.write_json(
            "/runner/phase",
            self._log_ns(t_ns),
            {"phase": phase.name, "phase_id": int(phase), "reason": reason},
        )
        level = "ERROR" if phase == Phase.ABORT else "INFO"
        self._event(t_ns, level, "phase", f"{old.name} -> {phase.name}: {reason}")
        if phase in (Phase.DONE, Phase.ABORT):
            self.outcome_reason = reason
            self._stop_at_ns = t_ns + int(self.p.run.stop_hold_s * NS)
            # safe stop: hold where the tool is now, not where the run started
            self._hold_pose = self._last_pose.copy()

    def abort(self, t_ns: int, reason: str) -> None:
        """End the run now with a safe stop."""
        if self.phase not in (Phase.DONE, Phase.ABORT):
            self._set_phase(t_ns, Phase.ABORT, reason)

    # -- the run --------------------------------------------------------------
    def run(self) -> RunOutcome:
        """Connect, loop until DONE/ABORT plus the safe-stop hold, close."""
        cycles = 0
        last_t = 0
        p = self.p
        try:
            self.robot.connect()
            self.sensor.start()
            first = True
            clock = time.perf_counter
            t_wait = clock()
            for m in self.robot.measurements():
                self.timings["driver"] += clock() - t_wait
                if first:
                    self._setup(m)
                    first = False
                t_ns = m.time_ns - (self._t0_ns or 0)
                last_t = t_ns
                cycles += 1
                self._cycle(m, t_ns)
                if self._stop_at_ns is not None and t_ns >= self._stop_at_ns:
                    break
                if t_ns >= p.run.timeout_s * NS and self.phase not in (Phase.DONE, Phase.ABORT):
                    self._set_phase(t_ns, Phase.DONE, "timeout")
                t_wait = clock()
        except DriverError as exc:
            self.abort(last_t, f"link lost: {exc}")
            self._event(last_t, "ERROR", "fault", str(exc))
        except KeyboardInterrupt:
            self.abort(last_t, "interrupted")
        finally:
            try:
                self.sensor.stop()
            finally:
                self.robot.close()
        if self.phase not in (Phase.DONE, Phase.ABORT):
            self.abort(last_t, "robot stopped sending measurements")
        return RunOutcome(
            phase=self.phase,
            aligned=self.aligned,
            reason=self.outcome_reason,
            cycles=cycles,
            duration_s=last_t / NS,
            contacts=self.contacts,
            breaks=self.breaks,
            events=self.events,
        )

    def _setup(self, m: Measurement) -> None:
        p = self.p
        self._t0_ns = m.time_ns
        cycle_s = m.cmd_sample_time if m.cmd_sample_time > 0 else 0.005
        self.cycle_s = cycle_s
        self.wf = WrenchFilter(p.estimation.wrench)
        self.mf = MotionFilter(p.estimation.motion, cycle_s)
        self.detector = ContactDetector(p.estimation.contact)
        self.force = ForceController(p.align, cycle_s)
        self.impedance = ImpedanceController(p.approach)
        self._tare_needed = max(1, round(p.run.tare_s * 1000))  # F/T samples (~1 kHz)
        self._start_pose = m.msr_cart_pos.copy()
        self._hold_pose = m.msr_cart_pos.copy()
        self._r_tare = m.msr_cart_pos[:3, :3].copy()
        self._event(0, "INFO", "phase", f"start: {p.name} ({p.method})")
        self.rec.write_json("/runner/phase", self._log_ns(0),
                            {"phase": "CONNECT", "phase_id": 0, "reason": "start"})

    def _cycle(self, m: Measurement, t_ns: int) -> None:
        p = self.p
        clock = time.perf_counter
        tm = self.timings
        t_a = clock()
        ft = self.sensor.samples()
        pose = m.msr_cart_pos
        self._last_pose = pose
        r = pose[:3, :3]
        comp = ft.wrench
        if p.estimation.tool_load.mass_kg > 0.0 and len(ft):
            accel = self.mf.accel_base[:3] if p.estimation.inertial_compensation else None
            comp = ft.wrench - p.estimation.tool_load.wrench(r, accel)

        # --- watchdogs (every phase) ---------------------------------------
        if len(ft):
            self._last_ft_ns = int(ft.time_ns[-1]) - (self._t0_ns or 0)
            if np.any(ft.status & SATURATION_BIT):
                self.abort(t_ns, "F/T sensor saturated")
            f_max = float(np.max(np.linalg.norm(ft.wrench[:, :3], axis=1)))
            t_max = float(np.max(np.linalg.norm(ft.wrench[:, 3:], axis=1)))
            if self.wf.tared:
                b = self.wf.bias
                f_max = float(np.max(np.linalg.norm(comp[:, :3] - b[:3], axis=1)))
                t_max = float(np.max(np.linalg.norm(comp[:, 3:] - b[3:], axis=1)))
            if f_max > p.limits.max_force_n:
                self.abort(t_ns, f"force limit: |f| = {f_max:.1f} N > {p.limits.max_force_n} N")
            if t_max > p.limits.max_torque_nm:
                self.abort(
                    t_ns, f"torque limit: |t| = {t_max:.2f} N m > {p.limits.max_torque_nm} N m"
                )
        since = t_ns - (self._last_ft_ns if self._last_ft_ns is not None else 0)
        if since > p.limits.stale_ft_s * NS:
            self.abort(t_ns, f"stale F/T data: no sample for {since / NS * 1e3:.0f} ms")
        commanding = self.phase not in (Phase.CONNECT,)
        bad_link = m.quality == FriQuality.UNACCEPTABLE or (
            commanding and m.state != FriState.CMD
        )
        self._bad_link_cycles = self._bad_link_cycles + 1 if bad_link else 0
        if self._bad_link_cycles >= p.limits.link_lost_cycles:
            self.abort(t_ns, f"link lost: state {m.state.name}, quality {m.quality.name}")
        if self.stop_requested():
            self.abort(t_ns, "stop requested (Ctrl-C / SIGTERM)")

        # --- estimation ------------------------------------------------------
        t_b = clock()
        tm["sensor"] += t_b - t_a
        self.mf.update(pose)
        twist = self.mf.twist_tcf(pose)
        if self.phase == Phase.CONNECT:
            if len(ft):
                self._tare.append(np.asarray(comp))
        else:
            self.wf.update(comp, self.cycle_s)
        w = self.wf.wrench
        event = self.detector.update(t_ns, w) if self.wf.tared else None

        # --- limits on motion ------------------------------------------------
        if self.phase in (Phase.APPROACH, Phase.ALIGN):
            speed = float(np.linalg.norm(twist[:3]))
            if speed > p.limits.max_speed_mps:
                self.abort(t_ns, f"speed limit: {speed:.3f} m/s > {p.limits.max_speed_mps} m/s")
            offset = self._start_pose[:3, :3].T @ (pose[:3, 3] - self._start_pose[:3, 3])
            if np.any(np.abs(offset) > np.asarray(p.limits.workspace_m)):
                self.abort(t_ns, f"workspace limit: offset {np.round(offset, 3).tolist()} m")

        # --- phase logic -----------------------------------------------------
        t_c = clock()
        tm["estimation"] += t_c - t_b
        self._phase_logic(m, t_ns, event, w)

        # --- command ---------------------------------------------------------
        total = self._command(m, t_ns, w, twist)
        self.robot.send(self._cmd)

        # --- recording -------------------------------------------------------
        t_d = clock()
        tm["control"] += t_d - t_c
        self._record(m, t_ns, ft, w, twist, total)
        tm["recording"] += clock() - t_d
        if self.progress is not None and t_ns >= self._next_progress_ns:
            self._next_progress_ns = t_ns + NS // 10
            self.progress(Progress(self.phase, t_ns / NS, -w[2], self.contacts, self.breaks))

    def _phase_logic(
        self, m: Measurement, t_ns: int, event: ContactEvent | None, w: np.ndarray
    ) -> None:
        p = self.p
        ev_kind = event.kind if event is not None else None
        if ev_kind == "made":
            self.contacts += 1
            self._event(t_ns, "INFO", "contact", f"contact made (#{self.contacts})")
        elif ev_kind == "broken":
            self._event(t_ns, "WARNING", "contact", "contact broken")
        if self.phase == Phase.CONNECT:
            n = sum(len(x) for x in self._tare)
            if n >= self._tare_needed and m.state == FriState.CMD:
                self.wf.tare(np.concatenate(self._tare))
                b = self.wf.bias
                bias = np.round(b, 3).tolist()
                self._event(t_ns, "INFO", "tare", f"tared from {n} samples; bias {bias}")
                self._hold_pose = m.msr_cart_pos.copy()
                self._start_pose = m.msr_cart_pos.copy()
                self.impedance.start(m.msr_cart_pos)
                self._set_phase(t_ns, Phase.APPROACH, "sensor tared, link in CMD")
        elif self.phase == Phase.APPROACH:
            if self.detector.in_contact:
                if self._first_contact_z is None:
                    self._first_contact_z = float(self._tcf_offset(m)[2])
                self.force.reset()
                self._set_phase(t_ns, Phase.ALIGN, "contact")
        elif self.phase == Phase.ALIGN:
            if not self.detector.in_contact:
                self.breaks += 1
                self.impedance.start(m.msr_cart_pos)
                self._aligned_since_ns = None
                self._set_phase(t_ns, Phase.APPROACH, f"contact lost (break #{self.breaks})")
                return
            if self._aligned_now(m, w):
                if self._aligned_since_ns is None:
                    self._aligned_since_ns = t_ns
                if t_ns - self._aligned_since_ns >= p.alignment.hold_s * NS:
                    self.aligned = True
                    self._event(t_ns, "INFO", "aligned", "funnels aligned")
                    self._set_phase(t_ns, Phase.DONE, "aligned")
            else:
                self._aligned_since_ns = None

    def _tcf_offset(self, m: Measurement) -> np.ndarray:
        d = m.msr_cart_pos[:3, 3] - self._start_pose[:3, 3]
        out: np.ndarray = self._start_pose[:3, :3].T @ d
        return out

    def _aligned_now(self, m: Measurement, w: np.ndarray) -> bool:
        a = self.p.alignment
        use_truth = a.source == "truth" or (a.source == "auto" and m.truth is not None)
        if use_truth:
            t = m.truth
            if t is None:
                return False
            if t.seated:
                return True
            return (
                abs(t.lateral_error) <= a.lateral_tol_m
                and abs(math.degrees(t.yaw_error)) <= a.yaw_tol_deg
                and t.insertion >= a.min_insertion_m
            )
        if self._first_contact_z is None:
            return False
        advanced = float(self._tcf_offset(m)[2]) - self._first_contact_z
        return advanced >= a.seated_depth_m and abs(float(w[1])) <= a.lateral_force_n

    def _command(self, m: Measurement, t_ns: int, w: np.ndarray, twist: np.ndarray) -> np.ndarray:
        cmd = self._cmd
        krc = self.p.krc
        phase = self.phase
        self.force_terms = None
        self._impedance_wrench[:] = 0.0
        if phase == Phase.CONNECT:
            hold = Command.hold(m)
            cmd.flags, cmd.control = hold.flags, hold.control
            cmd.jnt_pos[:] = hold.jnt_pos
            cmd.cart_pos[:] = hold.cart_pos
            cmd.add_tcp_ft[:] = 0.0
            cmd.cart_stiffness[:] = krc.hold_stiffness
            cmd.cart_damping[:] = krc.hold_damping
            return self._zero6
        cmd.flags = CmdFlags.CARTPOS | CmdFlags.TCPFT | CmdFlags.CARTSTIFF | CmdFlags.CARTDAMP
        cmd.control = ControlMode.CART_IMPEDANCE
        if phase in (Phase.DONE, Phase.ABORT):
            cmd.cart_pos[:] = self._hold_pose
            cmd.add_tcp_ft[:] = 0.0
            cmd.cart_stiffness[:] = krc.hold_stiffness
            cmd.cart_damping[:] = krc.hold_damping
            return self._zero6
        cmd.cart_pos[:] = self._hold_pose
        cmd.cart_stiffness[:] = krc.cart_stiffness
        cmd.cart_damping[:] = krc.cart_damping
        elapsed_s = (t_ns - self._phase_start_ns) / NS
        if phase == Phase.ALIGN and self.p.method != "impedance":
            terms = self.force.update(w)
            self.force_terms = terms
            cmd.add_tcp_ft[:] = terms.total
            return terms.total
        if phase == Phase.ALIGN:
            # Method III: the impedance law continues along the same line
            elapsed_s = (t_ns - self._approach_anchor_ns) / NS
        else:
            self._approach_anchor_ns = self._phase_start_ns
        f = self.impedance.update(m.msr_cart_pos, twist, elapsed_s)
        self._impedance_wrench[:] = f
        cmd.add_tcp_ft[:] = f
        return f

    def _record(
        self, m: Measurement, t_ns: int, ft: FtSamples, w: np.ndarray, twist: np.ndarray,
        total: np.ndarray,
    ) -> None:
        rec = self.rec
        log_ns = self._log_ns(t_ns)
        rec.write_fields("/robot/measurement", log_ns, m)

        r = rec.record("/robot/link")
        r["answer_rate"] = m.answer_rate
        r["latency_s"] = m.latency
        r["jitter_s"] = m.jitter
        r["miss_rate"] = m.miss_rate
        r["miss_counter"] = m.miss_counter
        r["state"] = int(m.state)
        r["quality"] = int(m.quality)
        rec.write("/robot/link", log_ns)

        n = len(ft)
        if n:
            proto = rec.record("/ft/raw")
            recs = np.zeros(n, dtype=proto.dtype)
            recs["_cdr_header"] = proto["_cdr_header"][0]
            recs["wrench"] = ft.wrench
            recs["seq"] = ft.seq & 0xFFFFFFFF
            recs["status"] = ft.status
            times = ft.time_ns - (self._t0_ns or 0) + self.start_utc_ns
            rec.write_records("/ft/raw", times, recs)

        r = rec.record("/estimator/state")
        r["wrench"] = w
        r["wrench_std"] = self.wf.wrench_std
        r["bias"] = self.wf.bias
        r["twist_tcf"] = twist
        r["f_z"] = -w[2]
        r["n_samples"] = n
        r["in_contact"] = int(self.detector.in_contact)
        rec.write("/estimator/state", log_ns)

        r = rec.record("/control/terms")
        terms = self.force_terms or self._no_terms
        r["p"] = terms.p
        r["i"] = terms.i
        r["ri"] = terms.ri
        r["ff"] = terms.ff
        r["saturated"] = int(terms.saturated)
        r["impedance"] = self._impedance_wrench
        r["total"] = total
        r["f_ref"] = self._f_ref
        r["setpoint"] = self.impedance.setpoint.reshape(-1)
        r["phase"] = int(self.phase)
        rec.write("/control/terms", log_ns)

        rec.write_fields("/robot/command", log_ns, self._cmd)
        truth = m.truth
        if truth is not None:
            rec.write_fields("/sim/truth", log_ns, truth)

        if t_ns >= self._next_tf_ns:
            self._next_tf_ns = t_ns + int(self.p.run.tf_period_s * NS)
            rec.transform(log_ns, "base", "tool", m.msr_cart_pos)
            if truth is not None:
                rec.transform(log_ns, "base", "target", truth.target_pose)
