"""Metrics, tables and the paper's figures, from run recordings.

Everything here reads a :class:`~ffexp.recording.Recording`; a run's numbers
are never taken from anywhere else, so ``ffexp run``, ``ffexp analyze`` and
``ffexp compare`` agree by construction.

Times are seconds since the run's first cycle. "In ALIGN" means the cycles
whose ``/control/terms.phase`` is ALIGN. The approach-axis contact force is
``f_z = -w[2]`` (positive while pushing); lateral contact force and torque are
plotted as measured, ``w[1]`` and ``w[3]`` (the environment on the tool), so
that the applied inertia-reduction terms ``k w`` are visibly proportional.
"""

from __future__ import annotations

import json
import math
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base.types import NS_PER_S as NS
from ffexp import controllers
from ffexp.contracts import Phase, StopReason
from ffexp.errors import InputError
from ffexp.recording import Recording

if TYPE_CHECKING:
    from matplotlib.axes import Axes
    from matplotlib.figure import Figure

ALIGN = Phase.ALIGN
PHASE_COLOURS = {
    Phase.APPROACH: "#dbe9f6", Phase.ALIGN: "#e3f1dc", Phase.DONE: "#eeeeee", Phase.ABORT: "#f8d7d3"
}
#: f_z tracking is scored after this long in each ALIGN segment.
SETTLE_S = 1.0


@dataclass
class RunMetrics:
    """The numbers of one run (``ffexp analyze --json`` prints these keys)."""

    protocol: str
    method: str
    aligned: bool
    alignment_time_s: float | None
    first_contact_s: float | None
    contact_breaks: int
    break_times_s: list[float]
    mean_fz_align_n: float | None
    peak_abs_fz_n: float | None
    fz_tracking_rmse_n: float | None
    f_ref_n: float | None
    target_speed_after_contact_mps: float | None
    target_max_speed_mps: float | None
    target_displacement_m: float | None
    final_lateral_error_m: float | None
    final_yaw_error_deg: float | None
    mean_abs_wrench_align: list[float] | None
    peak_abs_wrench_align: list[float] | None
    duration_s: float
    aborted: str | None
    link: dict[str, float]
    complete: bool = True
    warnings: list[str] = field(default_factory=list)

    def to_json(self) -> str:
        return json.dumps(asdict(self), allow_nan=False, default=_json_default)


def _json_default(x: object) -> object:
    if isinstance(x, np.generic):
        return x.item()
    raise TypeError(type(x).__name__)


@dataclass
class RunSeries:
    """Per-cycle series of a run, aligned on the controller cycles."""

    t_s: np.ndarray
    phase: np.ndarray
    wrench: np.ndarray
    applied: np.ndarray
    f_ref: np.ndarray
    in_contact: np.ndarray


def series(rec: Recording) -> RunSeries:
    """The per-cycle signals the metrics and figures use."""
    est = rec.topic("/estimator/state")
    ctl = rec.topic("/control/terms")
    # a cut file (killed run, recovered) may end between a cycle's two messages:
    # keep the cycles both topics have
    times, ie, ic = np.intersect1d(est.log_time_ns, ctl.log_time_ns, return_indices=True)
    if len(times) == 0:
        raise InputError(f"{rec.path}: no controller cycles recorded")
    t0 = int(times[0])
    return RunSeries(
        t_s=(times - t0) / NS,
        phase=ctl["phase"][ic],
        wrench=est["wrench"][ie],
        applied=ctl["total"][ic],
        f_ref=ctl["f_ref"][ic],
        in_contact=est["in_contact"][ie].astype(bool),
    )


def run_info(rec: Recording) -> dict[str, Any]:
    """The run metadata (protocol name, method, ...) as recorded."""
    meta = rec.metadata.get("run", {})
    out: dict[str, Any] = dict(meta)
    try:
        out["protocol_resolved"] = json.loads(meta.get("protocol_json", "{}"))
    except json.JSONDecodeError:
        out["protocol_resolved"] = {}
    return out


def metrics(rec: Recording) -> RunMetrics:
    """Compute a run's metrics from its recording."""
    s = series(rec)
    info = run_info(rec)
    t0_ns = int(rec.topic("/estimator/state").log_time_ns[0])
    phases = rec.json.get("/runner/phase")
    aborted: str | None = None
    aligned_at: float | None = None
    if phases is not None:
        for t_ns, msg in zip(phases.log_time_ns.tolist(), phases.messages, strict=True):
            phase = _phase_of(msg)
            if phase == Phase.ABORT:
                aborted = str(msg.get("reason", "aborted"))
            if phase == Phase.DONE and _ended_aligned(msg):
                aligned_at = (t_ns - t0_ns) / NS
    contact = s.in_contact
    made = np.flatnonzero(~contact[:-1] & contact[1:]) + 1
    first_contact = float(s.t_s[made[0]]) if made.size else (
        float(s.t_s[0]) if contact.size and contact[0] else None
    )
    lost = np.flatnonzero(contact[:-1] & ~contact[1:]) + 1
    breaks = [float(s.t_s[i]) for i in lost if s.phase[i - 1] == ALIGN]
    in_align = s.phase == ALIGN
    f_z = -s.wrench[:, 2]
    mean_fz = peak_fz = rmse = None
    mean_w = peak_w = None
    f_ref = None
    if in_align.any():
        mean_fz = float(np.mean(f_z[in_align]))
        peak_fz = float(np.max(np.abs(f_z[in_align])))
        mean_w = np.mean(np.abs(s.wrench[in_align]), axis=0).tolist()
        peak_w = np.max(np.abs(s.wrench[in_align]), axis=0).tolist()
        force_control = controllers.tracks_force_reference(str(info.get("method", "")))
        f_ref = float(np.median(s.f_ref[in_align, 2])) if force_control else None
        settled = in_align & (_time_in_phase(s) >= SETTLE_S)
        if settled.any() and force_control:
            rmse = float(np.sqrt(np.mean((f_z[settled] - s.f_ref[settled, 2]) ** 2)))
    speed_mean = speed_max = disp = lat = yaw = None
    truth = rec.topics.get("/sim/truth")
    if truth is not None and len(truth):
        tt = (truth.log_time_ns - t0_ns) / NS
        speed = np.hypot(truth["target_twist"][:, 0], truth["target_twist"][:, 1])
        after = tt >= first_contact if first_contact is not None else np.zeros_like(tt, bool)
        if after.any():
            speed_mean = float(np.mean(speed[after]))
            speed_max = float(np.max(speed[after]))
            p0 = truth["target_pose"][after][0].reshape(4, 4)[:3, 3]
            p1 = truth["target_pose"][-1].reshape(4, 4)[:3, 3]
            disp = float(np.linalg.norm(p1 - p0))
        lat = float(truth["lateral_error"][-1])
        yaw = math.degrees(float(truth["yaw_error"][-1]))
    link = _link_summary(rec)
    return RunMetrics(
        protocol=str(info.get("protocol", rec.path.stem)),
        method=str(info.get("method", "")),
        aligned=aligned_at is not None,
        alignment_time_s=aligned_at,
        first_contact_s=first_contact,
        contact_breaks=len(breaks),
        break_times_s=breaks,
        mean_fz_align_n=mean_fz,
        peak_abs_fz_n=peak_fz,
        fz_tracking_rmse_n=rmse,
        f_ref_n=f_ref,
        target_speed_after_contact_mps=speed_mean,
        target_max_speed_mps=speed_max,
        target_displacement_m=disp,
        final_lateral_error_m=lat,
        final_yaw_error_deg=yaw,
        mean_abs_wrench_align=mean_w,
        peak_abs_wrench_align=peak_w,
        duration_s=float(s.t_s[-1]),
        aborted=aborted,
        link=link,
        complete=rec.complete,
        warnings=list(rec.warnings),
    )


def _phase_of(msg: dict[str, Any]) -> Phase | None:
    """The phase of a ``/runner/phase`` message (by its id)."""
    try:
        return Phase(int(msg.get("phase_id", -1)))
    except ValueError:
        return None


def _ended_aligned(msg: dict[str, Any]) -> bool:
    """A DONE message says the run ended aligned (its flag; files before the flag: the
    reason that the stop reason's value then was)."""
    if "aligned" in msg:
        return bool(msg["aligned"])
    return msg.get("reason") == StopReason.ALIGNED.value


def _time_in_phase(s: RunSeries) -> np.ndarray:
    """Seconds since the current phase segment began, per cycle."""
    starts = np.concatenate([[True], s.phase[1:] != s.phase[:-1]])
    seg_start_t = s.t_s[starts]
    seg_index = np.cumsum(starts) - 1
    out: np.ndarray = s.t_s - seg_start_t[seg_index]
    return out


def _link_summary(rec: Recording) -> dict[str, float]:
    link = rec.topics.get("/robot/link")
    if link is None or len(link) == 0:
        return {}
    q = link["quality"]
    return {
        "cycles": float(len(link)),
        "min_answer_rate": float(np.min(link["answer_rate"])),
        "max_latency_s": float(np.max(link["latency_s"])),
        "max_jitter_s": float(np.max(link["jitter_s"])),
        "miss_counter": float(link["miss_counter"][-1]),
        "fraction_below_ok": float(np.mean(q < 2)),
    }


# -- tables ----------------------------------------------------------------------
COMPARE_COLUMNS = (
    ("protocol", "protocol"),
    ("method", "method"),
    ("f_ref [N]", "f_ref_n"),
    ("k_xp", "k_xp"),
    ("k_yp", "k_yp"),
    ("contact [s]", "first_contact_s"),
    ("aligned [s]", "alignment_time_s"),
    ("breaks", "contact_breaks"),
    ("mean f_z [N]", "mean_fz_align_n"),
    ("peak |f_z| [N]", "peak_abs_fz_n"),
    ("f_z rmse [N]", "fz_tracking_rmse_n"),
    ("target v [m/s]", "target_speed_after_contact_mps"),
    ("aborted", "aborted"),
)


def compare_rows(runs: list[tuple[RunMetrics, dict[str, Any]]]) -> list[list[str]]:
    """One text row per run in :data:`COMPARE_COLUMNS` order."""
    rows = []
    for m, info in runs:
        proto = info.get("protocol_resolved", {})
        k_ri = proto.get("align", {}).get("k_ri")
        values: dict[str, Any] = asdict(m)
        values["k_xp"], values["k_yp"] = (k_ri[3], k_ri[1]) if k_ri else (None, None)
        if not controllers.tracks_force_reference(m.method):
            values["f_ref_n"] = None
        rows.append([_fmt(values.get(key)) for _title, key in COMPARE_COLUMNS])
    return rows


def _fmt(x: object) -> str:
    if x is None:
        return "-"
    if isinstance(x, bool):
        return "yes" if x else "no"
    if isinstance(x, float):
        return f"{x:.3g}"
    return str(x)


# -- figures ---------------------------------------------------------------------
def _shade_phases(ax: Axes, s: RunSeries) -> None:
    starts = np.flatnonzero(np.concatenate([[True], s.phase[1:] != s.phase[:-1]]))
    ends = np.concatenate([starts[1:], [len(s.phase) - 1]])
    for a, b in zip(starts, ends, strict=True):
        colour = PHASE_COLOURS.get(Phase(int(s.phase[a])))
        if colour:
            ax.axvspan(s.t_s[a], s.t_s[b], color=colour, lw=0, zorder=0)


def _legend_phases(ax: Axes) -> None:
    from matplotlib.patches import Patch

    handles, labels = ax.get_legend_handles_labels()
    for pid, colour in PHASE_COLOURS.items():
        handles.append(Patch(color=colour))
        labels.append(Phase(pid).name)
    ax.legend(handles, labels, fontsize=7, loc="upper left", ncols=2)


def wrench_figure(rec: Recording, title: str) -> Figure:
    """Contact wrench over time with f_ref and the phases (the paper's exp_all_wrench)."""
    from matplotlib.figure import Figure

    s = series(rec)
    fig = Figure(figsize=(7.5, 6.0), layout="constrained")
    axes = fig.subplots(3, 1, sharex=True)
    ax = axes[0]
    _shade_phases(ax, s)
    ax.plot(s.t_s, -s.wrench[:, 2], lw=0.9, label="f_z = -w_z (contact, pushing > 0)")
    if np.any(s.f_ref[:, 2]):
        ref = np.where(s.phase == ALIGN, s.f_ref[:, 2], np.nan)
        ax.plot(s.t_s, ref, "k--", lw=0.9, label="f_z ref")
    ax.set_ylabel("force Z [N]")
    _legend_phases(ax)
    ax = axes[1]
    _shade_phases(ax, s)
    ax.plot(s.t_s, s.wrench[:, 1], lw=0.9, color="tab:orange", label="w_y")
    ax.plot(s.t_s, s.wrench[:, 0], lw=0.7, color="tab:gray", label="w_x (vertical)")
    ax.set_ylabel("force [N]")
    ax.legend(fontsize=7, loc="upper left")
    ax = axes[2]
    _shade_phases(ax, s)
    ax.plot(s.t_s, s.wrench[:, 3], lw=0.9, color="tab:green", label="t_x")
    ax.set_ylabel("torque X [N m]")
    ax.set_xlabel("time since start [s]")
    ax.legend(fontsize=7, loc="upper left")
    for a in axes:
        a.grid(True, ls=":", color="gray")
    fig.suptitle(f"{title}: measured contact wrench (TCF, environment on tool)", fontsize=10)
    return fig


def applied_figure(rec: Recording, title: str) -> Figure:
    """f_z; contact vs applied force along Y; contact vs applied torque about X
    (the paper's exp_fc_tri, exp_fc_ti_1 and exp_fc)."""
    from matplotlib.figure import Figure

    s = series(rec)
    fig = Figure(figsize=(12.0, 3.6), layout="constrained")
    axes = fig.subplots(1, 3)
    panels = [
        ("(a) contact force along Z", -s.wrench[:, 2], s.applied[:, 2], "f_z [N]", "F*_z applied"),
        ("(b) force along Y", s.wrench[:, 1], s.applied[:, 1], "f_y [N]", "F*_y applied"),
        ("(c) torque about X", s.wrench[:, 3], s.applied[:, 3], "t_x [N m]", "T*_x applied"),
    ]
    for ax, (name, contact, applied, unit, applied_label) in zip(axes, panels, strict=True):
        _shade_phases(ax, s)
        ax.plot(s.t_s, contact, lw=0.9, label="contact (measured)")
        ax.plot(s.t_s, applied, lw=0.9, label=applied_label)
        if name.startswith("(a)") and np.any(s.f_ref[:, 2]):
            ax.plot(s.t_s, np.where(s.phase == ALIGN, s.f_ref[:, 2], np.nan), "k--", lw=0.9,
                    label="f_z ref")
        ax.set_title(name, fontsize=9)
        ax.set_xlabel("time since start [s]")
        ax.set_ylabel(unit)
        ax.grid(True, ls=":", color="gray")
        ax.legend(fontsize=7, loc="upper left")
    fig.suptitle(f"{title}: contact and applied wrench", fontsize=10)
    return fig


def campaign_figure(recs: list[tuple[str, Recording]]) -> Figure:
    """All runs' contact force along Z in one grid (the paper's exp_all_wrench)."""
    from matplotlib.figure import Figure

    n = len(recs)
    cols = 2 if n > 1 else 1
    rows = (n + cols - 1) // cols
    fig = Figure(figsize=(6.0 * cols, 3.0 * rows), layout="constrained")
    axes = np.atleast_1d(fig.subplots(rows, cols, squeeze=False)).ravel()
    for ax, (title, rec) in zip(axes, recs, strict=False):
        s = series(rec)
        _shade_phases(ax, s)
        ax.plot(s.t_s, -s.wrench[:, 2], lw=0.8, label="f_z")
        ax.plot(s.t_s, s.wrench[:, 1], lw=0.8, label="w_y")
        ax.plot(s.t_s, s.wrench[:, 3], lw=0.8, label="t_x [N m]")
        if np.any(s.f_ref[:, 2]):
            ax.plot(s.t_s, np.where(s.phase == ALIGN, s.f_ref[:, 2], np.nan), "k--", lw=0.8,
                    label="f_z ref")
        ax.set_title(title, fontsize=9)
        ax.set_xlabel("time since start [s]")
        ax.set_ylabel("[N], [N m]")
        ax.grid(True, ls=":", color="gray")
        ax.legend(fontsize=7, loc="upper left")
    for ax in axes[n:]:
        ax.set_visible(False)
    fig.suptitle("Contact wrench per method (TCF; f_z = -w_z pushing > 0)", fontsize=10)
    return fig


def write_run_figures(rec: Recording, out_dir: Path, name: str) -> list[Path]:
    """The per-run figures as PNG into ``out_dir``."""
    out_dir.mkdir(parents=True, exist_ok=True)
    paths = []
    for suffix, fig in (
        ("wrench", wrench_figure(rec, name)),
        ("applied", applied_figure(rec, name)),
    ):
        path = out_dir / f"{name}_{suffix}.png"
        fig.savefig(path, dpi=130)
        paths.append(path)
    return paths
