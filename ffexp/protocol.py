"""Experiment protocols (TOML -> pydantic): one run of the paper, and campaigns.

A run protocol names the method, the scene it runs in (simulator) and every
number of the experiment; the defaults are the paper's (Table exp_table:
approach impedance Z 500 N/m, damping 1; PI gains k_zp 1, k_zi 0.07).
"""

from __future__ import annotations

from pathlib import Path
from typing import Literal

from pydantic import Field, model_validator

from drivers.config import StrictModel, load_model
from ffexp.control import ForceControlConfig, ImpedanceConfig, Vec6
from ffexp.estimation import (
    ContactDetectorConfig,
    MotionFilterConfig,
    ToolLoad,
    WrenchFilterConfig,
)

#: The paper's methods: (i) force control with apparent inertia reduction,
#: (ii) force control alone, (iii) impedance control throughout.
Method = Literal["force_ri", "force", "impedance"]

METHOD_NAMES: dict[str, str] = {
    "force_ri": "Method I (force control + inertia reduction)",
    "force": "Method II (force control)",
    "impedance": "Method III (impedance control)",
}


class SceneRef(StrictModel):
    """The simulated rig: a scene file (relative to the protocol) and overrides."""

    file: str = "../data/scenes/paper.toml"
    set: list[str] = Field(default_factory=list, description="dotted.key=value overrides")


class KrcSettings(StrictModel):
    """The KRC's internal Cartesian impedance during the experiment (FRI).

    The paper sets X, rot-Y, rot-Z to maximal stiffness (gravity plane held)
    and Y, Z, rot-X to zero, and applies its controller through addTcpFT.
    Order ``[x, y, z, rx, ry, rz]`` in TCF.
    """

    cart_stiffness: Vec6 = (5000.0, 0.0, 0.0, 0.0, 300.0, 300.0)
    cart_damping: Vec6 = (0.7, 0.0, 0.0, 0.0, 0.7, 0.7)
    hold_stiffness: Vec6 = Field(
        (2000.0, 2000.0, 2000.0, 200.0, 200.0, 200.0),
        description="Stiffness of the safe stop: hold the pose on every axis.",
    )
    hold_damping: Vec6 = (0.7, 0.7, 0.7, 0.7, 0.7, 0.7)


class Limits(StrictModel):
    """Safety limits; crossing one ends the run in ABORT with a safe stop."""

    max_force_n: float = Field(
        60.0,
        gt=0,
        description="|f| of any F/T sample (bias removed). The funnels' first slip into "
        "the seat reaches ~35 N in the simulator; the Mini45 (SI-145-5) reads 145/290 N.",
    )
    max_torque_nm: float = Field(3.0, gt=0, description="|t| of any raw F/T sample.")
    max_speed_mps: float = Field(0.25, gt=0, description="Tool speed (motion filter).")
    workspace_m: tuple[float, float, float] = Field(
        (0.05, 0.15, 0.35), description="Half-widths of the box around the start pose (TCF)."
    )
    stale_ft_s: float = Field(0.05, gt=0, description="Longest gap without F/T samples.")
    link_lost_cycles: int = Field(
        10, ge=1, description="Consecutive cycles not in CMD or with UNACCEPTABLE quality."
    )


class Alignment(StrictModel):
    """When the funnels count as aligned.

    With ground truth (simulator): the tool is seated in the target funnel
    (the simulator's own test) or its lateral and yaw errors are within
    tolerance past ``min_insertion_m``. Without ground truth: the tool has
    advanced ``seated_depth_m`` along Z since first contact and the lateral
    force has stayed below ``lateral_force_n``. Either must hold ``hold_s``.
    """

    source: Literal["auto", "truth", "settings"] = "auto"
    lateral_tol_m: float = Field(0.002, gt=0)
    yaw_tol_deg: float = Field(2.0, gt=0)
    min_insertion_m: float = Field(0.02, ge=0)
    seated_depth_m: float = Field(0.03, gt=0)
    lateral_force_n: float = Field(0.3, gt=0)
    hold_s: float = Field(0.2, ge=0)


class RunSettings(StrictModel):
    """Timing of the run."""

    timeout_s: float = Field(30.0, gt=0, description="Simulated/robot time for the whole run.")
    tare_s: float = Field(0.25, gt=0, description="Free-space time used to tare the sensor.")
    stop_hold_s: float = Field(0.1, ge=0, description="Safe-stop hold after DONE/ABORT.")
    tf_period_s: float = Field(0.02, gt=0, description="Period of /tf transforms in the log.")


class Estimation(StrictModel):
    """Filters, tool load and contact detection (see ffexp.estimation)."""

    wrench: WrenchFilterConfig = WrenchFilterConfig()
    motion: MotionFilterConfig = MotionFilterConfig()
    tool_load: ToolLoad = ToolLoad()
    inertial_compensation: bool = Field(
        True,
        description="Also remove the tool's inertia (mass x acceleration from the motion "
        "filter) from the reading; needs tool_load.mass_kg.",
    )
    contact: ContactDetectorConfig = ContactDetectorConfig()


class RunProtocol(StrictModel):
    """One experiment: ``protocols/method*.toml``."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    method: Method
    seed: int = 0
    scene: SceneRef = SceneRef()
    run: RunSettings = RunSettings()
    approach: ImpedanceConfig = ImpedanceConfig()
    align: ForceControlConfig = ForceControlConfig()
    krc: KrcSettings = KrcSettings()
    estimation: Estimation = Estimation()
    limits: Limits = Limits()
    alignment: Alignment = Alignment()
    paper: dict[str, float | str] = Field(
        default_factory=dict,
        description="The paper's reported values for this run (Table res_par), for comparison.",
    )

    @model_validator(mode="after")
    def _method_matches_gains(self) -> RunProtocol:
        if self.method == "force" and any(self.align.k_ri):
            raise ValueError("method 'force' (Method II) has no inertia reduction: set k_ri to 0")
        return self


class CampaignEntry(StrictModel):
    protocol: str
    set: list[str] = Field(default_factory=list)


class CampaignProtocol(StrictModel):
    """Several runs compared side by side: ``protocols/paper.toml``."""

    name: str = Field(min_length=1, pattern=r"^[A-Za-z0-9_.-]+$")
    description: str = ""
    runs: list[CampaignEntry] = Field(min_length=1)


def load_run_protocol(path: Path, overrides: list[str] | tuple[str, ...] = ()) -> RunProtocol:
    """Read a run protocol with ``--set`` overrides (one-line errors)."""
    return load_model(RunProtocol, path, overrides)


def scene_path(protocol_path: Path, protocol: RunProtocol) -> Path:
    """The scene file, relative to the protocol file's folder."""
    p = Path(protocol.scene.file)
    return p if p.is_absolute() else (protocol_path.parent / p)
