"""The impact protocol (``protocols/hil_impact.toml``): which scene, how the chaser's
tool meets the rendered target, and faults to inject. Light: no numpy at import."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path
from typing import Annotated

from pydantic import Field

from drivers.config import StrictModel
from ffexp.filekind import load_as

__all__ = ["DeviceLink", "FaultSettings", "HilProtocol", "ImpactSettings", "LinkSettings",
           "load_hil_protocol"]


class ImpactSettings(StrictModel):
    """The chaser's tool, held stiff, meets the mock-up's face."""

    speed_mps: Annotated[float, Field(gt=0.0, le=1.0)] = Field(
        0.1, description="The tool's speed into the mock-up's -x face.")
    gap_m: Annotated[float, Field(ge=0.0, le=0.1)] = Field(
        0.002, description="Tool tip to face at the start.")
    offset_m: float = Field(
        0.0, description="Where the tip meets the face, along the target's y from its centre "
        "(off-centre: the target turns, its effective mass falls).")
    after_s: Annotated[float, Field(gt=0.0, le=10.0)] = Field(
        0.1, description="How long the run goes on once the contact has ended.")
    duration_s: Annotated[float, Field(gt=0.0, le=60.0)] = Field(
        1.0, description="The longest run.")


class FaultSettings(StrictModel):
    """Faults to inject (fault tests; none by default)."""

    ft_stale_at_s: Annotated[float, Field(ge=0.0)] | None = Field(
        None, description="The carrier's F/T sensor delivers nothing from this time on.")
    link_lost_at_s: Annotated[float, Field(ge=0.0)] | None = Field(
        None, description="The carrier's link stops answering from this time on.")
    carrier_emulator_killed_at_s: Annotated[float, Field(ge=0.0)] | None = Field(
        None, description="Over the wire ([link]): the carrier's emulator is killed at the "
        "first cycle from this time on (its connection closes under the carrier's link).")


class DeviceLink(StrictModel):
    """One arm's emulated controller and where it listens."""

    emulator: Annotated[str, Field(min_length=1)] = Field(
        description="The emulated controller that serves the arm (an `ffexp emulate --robot` "
        "name whose family serves an arm of a shared world).")
    host: str = Field("127.0.0.1", description="Its loopback address.")
    port: Annotated[int, Field(ge=0, le=65535)] = Field(
        0, description="Its port (0: any free one).")


class LinkSettings(StrictModel):
    """Both arms over the wire, each behind its own emulator on one shared world, in
    lockstep (carrier.model = 'arm'): served by this run, each link a socket."""

    chaser: DeviceLink
    carrier: DeviceLink


class HilProtocol(StrictModel):
    """An impact on a target rendered by a carrier robot."""

    name: Annotated[str, Field(pattern=r"^[A-Za-z0-9_.-]+$")] = "hil_impact"
    description: str = ""
    scene: Path = Field(description="The scene (relative to the protocol file); its "
                        "[carrier], [contact], [ft_sensor] and [target] tables are used.")
    seed: int = 0
    scene_set: tuple[str, ...] = Field((), description="Scene overrides (KEY=VALUE, as "
                                       "--scene-set), applied before the command line's.")
    impact: ImpactSettings = ImpactSettings()
    faults: FaultSettings = FaultSettings()
    link: LinkSettings | None = Field(None, description="Run over the wire (both arms behind "
                                      "their own emulators); none: in process.")


def load_hil_protocol(path: Path, overrides: tuple[str, ...] = ()) -> HilProtocol:
    """Read and validate an impact protocol; its scene path taken relative to the file.

    Raises:
        ConfigError: ``"<path>: <field>: <message>"``.
    """
    proto = load_as(HilProtocol, path, overrides, "impact protocol")
    if not proto.scene.is_absolute():
        proto = proto.model_copy(update={"scene": path.parent / proto.scene})
    return proto


def split_sets(sets: Sequence[str], scene_sets: Sequence[str]
               ) -> tuple[tuple[str, ...], tuple[str, ...]]:
    """``--set`` and ``--scene-set`` as (the protocol's overrides, the scene's): a ``--set
    scene.KEY=VALUE`` is the scene's ``KEY=VALUE``, as ``--scene-set KEY=VALUE`` is (the
    forms the run commands take)."""
    scene = tuple(s.removeprefix("scene.") for s in sets if s.startswith("scene."))
    return (tuple(s for s in sets if not s.startswith("scene.")),
            (*scene_sets, *scene))
