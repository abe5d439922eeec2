"""The two-arm world the carrier loop drives, as the loop sees it (a protocol, no physics
here), and where its parts stand (:func:`arm_layout`). Pure maths, no I/O.

The world holds both arms: the chaser (the scene's arm at its start pose, its tool's
motion imposed: held stiff) and the carrier (``carrier.arm``, position-controlled), with
the target's mock-up on the carrier's flange behind a simulated F/T sensor. Each carrier
cycle the loop gives both arms' joint targets (the carrier's as ``servoJ`` would take
them: position and velocity) and gets back the carrier's joints (as a UR reports
``actual_q`` and ``actual_qd``) and the F/T samples that reached it. The same protocol is
met in process (:mod:`drivers.world.twoarm`) and over the wire, each arm behind its own
emulator.

Geometry (:func:`arm_layout`): the chaser's tool tip starts where its arm's start pose puts
it and moves along the world's +x (the tool axis of the paper's pose); the mock-up's
centre, which is the rendered body's centre, starts ``gap + half its length`` ahead (and
``impact.offset_m`` aside), its axes the world's; it is mounted by its +x face on the
carrier's flange through the sensor (the flange's z axis along world -x); the carrier's
base stands at :data:`CARRIER_BASE_FROM_FLANGE_M` from its start flange, the arm in the
elbow-up posture :data:`CARRIER_SEED_Q` converges to.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Final, Protocol

import numpy as np

from drivers.base.types import F64
from drivers.carrier.kinematics import ArmChain, IkError
from drivers.description.funnel import tool_tip_offset
from drivers.description.scene import ARMS, Scene
from drivers.errors import ConfigError

__all__ = ["CARRIER_BASE_FROM_FLANGE_M", "CARRIER_SEED_Q", "ArmLayout", "CarrierPlant",
           "JointLink", "JointReading", "PlantCycle", "WirePlant", "arm_layout"]

#: The carrier's base from its flange at the start [m] (our layout: the flange at about
#: two thirds of a UR5e's 0.85 m reach, level with the shoulder's height above the base).
CARRIER_BASE_FROM_FLANGE_M: Final = (0.45, -0.15, -0.25)
#: The posture the carrier's start is solved from (elbow up, wrist towards -x).
CARRIER_SEED_Q: Final = (np.pi, -1.9, -1.6, -1.2, np.pi / 2, 0.0)


@dataclass
class PlantCycle:
    """What the loop gets from the world at a carrier cycle's end."""

    t_s: float
    carrier_q: F64
    carrier_qd: F64
    samples: list[tuple[float, F64]] = field(default_factory=list)
    """F/T samples that reached the loop during the cycle: (sample time, reading: the
    force the mock-up puts on the sensor and its torque about the mock-up's centre,
    world frame)."""
    fine: list[tuple[float, ...]] = field(default_factory=list)
    """The contact's truth per physics step: time, depth, normal force, the mock-up contact
    point's normal velocity, the tool tip's x (from the body's start centre)."""
    lost: str | None = None
    """The carrier's link was lost (which and why): the loop holds, the chaser stops."""


class CarrierPlant(Protocol):
    """Both arms in one world, one carrier cycle at a time."""

    def start(self) -> PlantCycle:
        """The state at time 0 (nothing sampled yet)."""

    def step(self, carrier_q: F64, carrier_qd: F64, chaser_q: F64,
             chaser_qd: F64) -> PlantCycle:
        """One carrier cycle with these joint targets (reached at the cycle's end)."""

    def close(self) -> None:
        """Release what it holds."""


@dataclass(frozen=True)
class ArmLayout:
    """Where the two arms and the mock-up stand (see the module)."""

    chaser: ArmChain
    chaser_q0: F64
    carrier: ArmChain
    carrier_q0: F64
    centre_m: F64
    """The rendered body's (and mock-up's) start centre, world."""
    mount: F64
    """The mock-up's frame in the carrier's flange frame (4x4)."""
    sensor_in_mockup_m: F64
    """The F/T sensor's tool-side face in the mock-up's frame."""
    torque_limits_nm: tuple[float, ...]


def _mount(scene: Scene) -> tuple[F64, F64]:
    half = 0.5 * scene.target.size[0]
    mount = np.eye(4)
    mount[:3, :3] = np.array([[0.0, 0.0, 1.0], [0.0, 1.0, 0.0], [-1.0, 0.0, 0.0]])
    mount[:3, 3] = (0.0, 0.0, scene.tool.sensor_height + half)
    return mount, np.array([half, 0.0, 0.0])


def _torque_limits(name: str, scene: Scene) -> tuple[float, ...]:
    from drivers.description import fr3, ur5e

    if name == "ur5e":
        return tuple(ur5e.TORQUE_LIMITS_NM)
    if name == "fr3":
        return tuple(fr3.TORQUE_LIMITS_NM)
    default = scene.arm.model_fields["torque_limits"].default
    return tuple(float(v) for v in default)


def arm_layout(scene: Scene, gap_m: float, offset_m: float) -> ArmLayout:
    """The layout of an impact with ``gap_m`` from tip to face, ``offset_m`` aside."""
    tool = np.eye(4)
    tool[2, 3] = scene.tool.sensor_height + tool_tip_offset(scene)
    bx, by, bz = scene.arm.base_pos
    chaser = ArmChain(scene.arm.description, (bx, by, bz), tool)
    q0 = np.asarray(scene.arm.q_init, dtype=np.float64)
    tip0 = chaser.pose(q0)[:3, 3]
    half = 0.5 * scene.target.size[0]
    centre = tip0 + np.array([gap_m + half, -offset_m, 0.0])
    mount, sensor = _mount(scene)
    start = np.eye(4)
    start[:3, 3] = centre
    flange = start @ np.linalg.inv(mount)
    base = tuple(float(v) for v in flange[:3, 3] + np.asarray(CARRIER_BASE_FROM_FLANGE_M))
    name = scene.carrier.arm
    carrier = ArmChain(ARMS[name], (base[0], base[1], base[2]), mount)
    seed = np.asarray(CARRIER_SEED_Q[:carrier.arm.joints], dtype=np.float64)
    if carrier.arm.joints > len(seed):
        seed = np.concatenate((seed, np.zeros(carrier.arm.joints - len(seed))))
    try:
        q_c = carrier.solve_ik(start, seed, iterations=200)
    except IkError as exc:
        raise ConfigError(scene.name, "carrier.arm", f"the {name} cannot reach the mock-up's "
                          f"start: {exc}") from None
    return ArmLayout(chaser, q0, carrier, q_c, centre, mount, sensor,
                     _torque_limits(name, scene))


@dataclass(frozen=True)
class JointReading:
    """One cycle's state of an arm as its link reports it."""

    t_s: float
    q: F64
    qd: F64
    samples: list[tuple[float, F64]] = field(default_factory=list)
    """The F/T samples that reached the controller during the cycle (a carrier's)."""


class JointLink(Protocol):
    """An arm's joint-position link (a family's, over its wire): each cycle one reading,
    one answer with the joint targets (position and velocity, as ``servoJ`` takes them).
    A lost link raises :class:`~drivers.errors.DriverError` from :meth:`read`."""

    name: str
    """The device and where it is, for messages (``carrier at 127.0.0.2:30004``)."""

    def read(self) -> JointReading:
        """The next cycle's state (blocks until it comes)."""

    def send(self, q: F64, qd: F64) -> None:
        """The joint targets answering the last reading."""

    def close(self) -> None:
        """Close the link."""


class WirePlant:
    """Both arms over their links, each behind its own emulator (a
    :class:`CarrierPlant`). ``truth`` drains the contact's truth rows the emulated world
    produced since the last call (a simulator's, as its truth is recorded; empty without
    one). When the carrier's link is lost the chaser goes on alone: the cycle says
    :attr:`PlantCycle.lost`, the carrier's state stays as last read."""

    def __init__(self, carrier: JointLink, chaser: JointLink,
                 truth: Callable[[], list[tuple[float, ...]]] | None = None) -> None:
        self.carrier, self.chaser, self._truth = carrier, chaser, truth
        self._last: JointReading | None = None
        self._lost: str | None = None

    def _read(self) -> PlantCycle:
        from drivers.errors import DriverError

        samples: list[tuple[float, F64]] = []
        if self._lost is None:
            try:
                reading = self.carrier.read()
                self._last = reading
                samples = reading.samples
            except DriverError as exc:
                self._lost = f"carrier link lost: {exc}"
                self.carrier.close()
        chaser = self.chaser.read()
        last = self._last
        assert last is not None, "the carrier's first reading is read before any cycle"
        fine = self._truth() if self._truth is not None else []
        return PlantCycle(chaser.t_s, last.q, last.qd, samples, fine, self._lost)

    def start(self) -> PlantCycle:
        return self._read()

    def step(self, carrier_q: F64, carrier_qd: F64, chaser_q: F64,
             chaser_qd: F64) -> PlantCycle:
        from drivers.errors import DriverError

        if self._lost is None:
            try:
                self.carrier.send(carrier_q, carrier_qd)
            except DriverError as exc:
                self._lost = f"carrier link lost: {exc}"
                self.carrier.close()
        self.chaser.send(chaser_q, chaser_qd)
        return self._read()

    def close(self) -> None:
        self.carrier.close()
        self.chaser.close()
