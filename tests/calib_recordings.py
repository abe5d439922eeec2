"""Short recordings made by the simulator at parameters set here (none at the scene's
defaults), shared by the calibration tests."""

from __future__ import annotations

from pathlib import Path

from ffexp.experiment import run_file
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method2_f08.toml"
SCENE = ROOT / "data/scenes/paper.toml"
#: The rig's "true" values (the scene's defaults: delay 1, mu 0.0085, scale 0.00069, e 0.5).
TRUTH = {"fri.command_delay_cycles": 2, "target.mu": 0.006, "arm.friction_scale": 0.0009,
         "contact.restitution": 0.3}


def record(out: Path, extra: list[str], timeout_s: float, *, seed: int = 1,
           rig: tuple[str, ...] = ("tracker.type=sim",), driver: str = "sim") -> Path:
    """One run of Method II at :data:`TRUTH` (plus ``extra`` scene overrides)."""
    sets = [f"{k}={v}" for k, v in TRUTH.items()] + extra
    scene_set = "scene.set=[" + ", ".join(f'"{s}"' for s in sets) + "]"
    result = run_file(PROTOCOL, [f"run.timeout_s={timeout_s}", f"seed={seed}", scene_set],
                      rig=RigChoice(driver=driver, overrides=rig), out_dir=out)
    return result.path


def glide(out: Path) -> Path:
    """The target set gliding by an impulse, far from the arm (no contact)."""
    return record(out, ["target.distance=0.2", "target.velocity=[0.0, 0.1, 0.0]"], 1.6)


def push(out: Path, rig: tuple[str, ...] = ("tracker.type=sim",)) -> Path:
    """The approach into the funnel from close by and off its axis (contact after 1 s)."""
    return record(out, ["target.distance=0.004", "target.lateral=0.028"], 2.0, rig=rig)
