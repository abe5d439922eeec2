"""Scene files: the physical rig as TOML, validated by pydantic.

A scene describes the rig: the arm (where it stands, its start pose, joint
friction, the limits of the KRC's internal controller and its FRI timing), the
tool and the F/T sensor, the air-bed target with its funnel and hose, and the
funnel contact, plus the physics settings of the simulator that builds it
(:class:`~drivers.world.world.SimWorld`). The emulated controllers and
``ffexp.scene3d`` read the same file; nothing here does I/O beyond loading it.
Every field has the paper's rig as its default, so an empty file is the paper's
rig; ``data/scenes/paper.toml`` spells it out.

Load with :func:`load_scene`, which reports any problem as one line
``file: field: message`` (a :class:`~drivers.errors.ConfigError`).
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from pathlib import Path
from typing import Annotated, Literal

import numpy as np
from numpy.typing import NDArray
from pydantic import Field, field_validator, model_validator

from drivers.config import (
    Floats2,
    Floats3,
    Floats6,
    NonNeg,
    PerJoint,
    PosFloat,
    StrictModel,
    load_model,
)
from drivers.description.arm import ArmDescription
from drivers.description.carrier import CarrierSettings
from drivers.description.fr3 import FR3
from drivers.description.lwr4 import LWR4
from drivers.description.ur5e import UR5E

#: The arm models a scene may name (``arm.model``), each its published description.
ARMS: dict[str, ArmDescription] = {"lwr4": LWR4, "ur5e": UR5E, "fr3": FR3}


class PhysicsSettings(StrictModel):
    """MuJoCo solver settings. ``timestep`` must divide the FRI cycle."""

    timestep: Annotated[float, Field(ge=1e-5, le=0.001)] = 0.001
    """[s] 10 us to 1 ms. Below 10 us a simulated second is over 100,000 steps: a typo
    such as ``1e-9`` would run for hours and fill the memory."""
    integrator: Literal["implicitfast", "implicit", "Euler", "RK4"] = "implicitfast"
    """MuJoCo's integrator. A body in free flight (``target.support = "free"``) keeps
    its energy and angular momentum only with ``RK4``: over 60 s of a tumbling 12 kg
    block at 1 ms, Euler gains 1.5e-3 of its energy and implicitfast loses as much,
    RK4 drifts below 1e-9 (measured: tests/test_zero_g.py; the zero-g scene uses it)."""
    impratio: Annotated[float, Field(ge=1.0)] = 10.0
    iterations: Annotated[int, Field(ge=1)] = 50
    tolerance: PosFloat = 1e-8
    gravity: NonNeg = 9.81
    """[m/s^2] along world -z; 0 for an orbit's micro-gravity (a target on
    ``support = "free"``: an air bed needs gravity to carry the target on its pads)."""
    settle_time: NonNeg = 0.05
    """Physics time run before t = 0 so the target settles on its pads (none in free
    flight: a free target starts at t = 0 where the scene puts it)."""


class FriTiming(StrictModel):
    """The scene's ``[fri]`` table: the FRI link's timing and mode as the KRC runs it."""

    cycle: Annotated[float, Field(ge=0.001, le=0.1)] = 0.005
    """FRI cycle [s] (``friOpen(ms)``: 1 to 100 ms). The paper runs 200 Hz."""
    control: Literal["cart_impedance", "joint_position", "joint_impedance"] = "cart_impedance"
    command_delay_cycles: Annotated[int, Field(ge=0, le=20)] = 1
    """Whole cycles from a measurement to the first cycle its answer acts in, in
    lockstep (:class:`~drivers.fri.emulate.krc.CommandDelay`). The KRC sends
    measurement k, the remote answers within the cycle and the KRC applies the
    answer at its next cycle at the earliest (Schreiber et al., ICRA 2010
    workshop, sec. V-B; the fact sheet ``fri_netft.md``): 1. 0 is the
    idealised loop in which a command acts in the cycle it answers. Real-time
    pacing over UDP adds none (its pipeline and the link are the delay)."""


class ControllerSettings(StrictModel):
    """The KRC's internal impedance controller and its limits.

    Stiffness order is ``[x, y, z, rx, ry, rz]`` in TCF (FRI sends
    ``[x, y, z, A(rz), B(ry), C(rx)]``; the codec reorders).
    """

    cart_stiffness_max: Floats2 = (5000.0, 300.0)
    """Upper limits [N/m, N m/rad]. Not confirmed for the LWR4+ by a primary
    source (fact sheet sec. 2): the commonly quoted 5000 / 300."""
    cart_stiffness: Floats6 = (5000.0, 0.0, 0.0, 0.0, 300.0, 300.0)
    """Initial stiffness: the paper's setting (X, rot-Y, rot-Z maximal; Y, Z, rot-X zero)."""
    cart_damping: Floats6 = (0.7, 0.0, 0.0, 0.0, 0.7, 0.7)
    jnt_stiffness_max: PosFloat = 5000.0
    """Joint stiffness upper limit [N m/rad] (CentroEPiaggio URDF ``max_stiffness``)."""
    jnt_position_stiffness: PosFloat = 3000.0
    """Stiffness [N m/rad] used to emulate the KRC's joint-position mode."""
    jnt_position_damping: Annotated[float, Field(ge=0.0, le=1.0)] = 0.7


class ArmSettings(StrictModel):
    """The arm (the LWR4+ unless ``model`` says otherwise): where it stands, its start pose,
    friction and torque limits. Every per-joint field has one value per joint of the model."""

    model: Annotated[str, Field(json_schema_extra={"enum": list(ARMS)})] = "lwr4"
    """The arm model, a name of the registry :data:`ARMS`: ``lwr4`` (KUKA LWR4+, the
    paper's), ``ur5e`` or ``fr3``; a new arm is one description module and one entry there."""

    @field_validator("model")
    @classmethod
    def _known_model(cls, value: str) -> str:
        if value not in ARMS:
            raise ValueError(f"unknown arm {value!r}; known: {', '.join(ARMS)}")
        return value
    base_pos: Floats3 = (0.0, 0.0, 0.0)
    q_init: PerJoint = (0.0, -0.3533, 0.0, 1.714, 0.0, 0.4965, 0.0)
    """Initial joint angles [rad]; the paper pose: flange horizontal along
    world +x, flange X up (so TCF X is vertical as in the paper)."""
    friction_scale: Annotated[float, Field(ge=0.0, le=1.0)] = 0.00069
    """Fraction of Jubien's drive-side friction that remains link-side under the
    KRC's torque control (not published). The paper's force-control ordering
    (Method I case I aligns at 0.8 N, Method II does not) holds only in a band of
    it of ratio about 1 + k_xp: Method II at 0.8 N slides below 0.000556 and
    Method I case I stops aligning with at most one break above 0.000858 (``ffexp
    limits``, nominal scene); 0.00069 is the band's geometric centre, so +-15 %
    stays inside it (docs/fidelity.md, drivers/world/NOTES.md)."""
    coulomb: PerJoint | None = None
    """Explicit joint Coulomb friction [N m]; overrides ``friction_scale``."""
    viscous: PerJoint | None = None
    """Explicit joint viscous friction [N m s/rad]; overrides ``friction_scale``."""
    static_ratio: Annotated[float, Field(ge=1.0, le=5.0)] = 1.3
    """Breakaway (static) over Coulomb friction (Stribeck curve, :mod:`drivers.world.friction`).
    No published value for the LWR4+ was found: an assumption of the order
    reported for harmonic-drive joints."""
    stribeck_speed: Annotated[float, Field(gt=0.0, le=1.0)] = 0.02
    """Joint speed [rad/s] over which friction falls from static to Coulomb (assumption)."""
    armature_scale: Annotated[float, Field(ge=0.0, le=1.0)] = 0.05
    """Fraction of Jubien's reflected rotor inertia seen link-side (assumption)."""
    torque_loop_r: Annotated[float, Field(ge=0.0, le=1.0)] | None = None
    """The joint torque loop's factor r = B_theta / B = 1 / (1 + K_T): with the DLR
    torque feedback the motor's friction and its rotor inertia both reach the link
    scaled by r (the flexible-joint form of Albu-Schaeffer, Ott, Hirzinger, IJRR 2007;
    the LWR4+'s K_T is not published, so r is the one unknown). When set, each joint's
    Coulomb and viscous friction are ``link_* + r *`` the model's drive-side values
    (Jubien, Gautier, Janot 2014 for the LWR4+) and its rotor inertia ``r *`` the
    published one, replacing ``friction_scale`` and ``armature_scale``. None: those two."""
    link_coulomb: PerJoint | None = None
    """Joint Coulomb friction after the torque sensor [N m] (output bearings: the torque
    loop does not reduce it), added with ``torque_loop_r``; None: the model's published
    values (the LWR4+: FloBaRoID's, :mod:`drivers.description.lwr4`; none: zero)."""
    link_viscous: PerJoint | None = None
    """As ``link_coulomb``, viscous [N m s/rad]."""
    torque_limits: PerJoint = (176.0, 176.0, 100.0, 100.0, 100.0, 38.0, 38.0)
    """[N m], CentroEPiaggio URDF effort limits (fact sheet sec. 1)."""

    @model_validator(mode="after")
    def _check_joints(self) -> ArmSettings:
        n = self.description.joints
        for name in ("q_init", "coulomb", "viscous", "link_coulomb", "link_viscous",
                     "torque_limits"):
            values = getattr(self, name)
            if values is not None and len(values) != n:
                raise ValueError(f"arm.{name} has {len(values)} values; the "
                                 f"{self.description.name} (arm.model {self.model!r}) has "
                                 f"{n} joints")
        return self

    @property
    def description(self) -> ArmDescription:
        """The model's published description."""
        return ARMS[self.model]

    def coulomb_friction(self) -> list[float]:
        """Explicit ``coulomb``; else with ``torque_loop_r`` ``link_coulomb + r *`` the
        model's published drive friction; else ``friction_scale`` of it (zero where none
        is published)."""
        if self.coulomb is not None:
            return list(self.coulomb)
        return self._scaled(self.description.drive_coulomb_nm,
                            self.link_coulomb or self.description.link_coulomb_nm)

    def viscous_friction(self) -> list[float]:
        """As :meth:`coulomb_friction`, viscous."""
        if self.viscous is not None:
            return list(self.viscous)
        return self._scaled(self.description.drive_viscous_nmsprad,
                            self.link_viscous or self.description.link_viscous_nmsprad)

    def rotor_fraction(self) -> float:
        """The fraction of the published rotor inertia the link sees: ``torque_loop_r``
        when set, else ``armature_scale``."""
        return self.armature_scale if self.torque_loop_r is None else self.torque_loop_r

    def _scaled(self, drive: tuple[float, ...] | None, link: tuple[float, ...] | None
                ) -> list[float]:
        n = self.description.joints
        drive_side = drive or (0.0,) * n
        if self.torque_loop_r is None:
            return [self.friction_scale * v for v in drive_side]
        after = link or (0.0,) * n
        return [a + self.torque_loop_r * v for a, v in zip(after, drive_side, strict=True)]


class FunnelGeometry(StrictModel):
    """A funnel: a hollow cone (target) or a solid cone on a nose sphere (tool).

    ``surface = "smooth"`` (the simulator's surfaces: :mod:`drivers.world.funnels`): the target is
    ``panels`` flat panels tangent to the cone, the tool a stack of spheres
    inscribed in its cone, axial scallops below ``scallop``. ``"capsules"``:
    the earlier faceted funnels, ``generators`` capsules of ``capsule_radius``.
    """

    half_angle_deg: Annotated[float, Field(gt=5.0, lt=80.0)] = 30.0
    depth: PosFloat = 0.065
    """Axial length of the cone [m]."""
    opening: PosFloat = 0.04
    """Radius of the cone's mouth (target) or base (tool) [m]."""
    surface: Literal["smooth", "capsules"] = "smooth"
    panels: Annotated[int, Field(ge=6, le=128)] = 24
    """Target, smooth: number of flat panels (creases turn by 360/panels deg).
    Cost grows with panels x tool spheres when the cones nest (every pair's
    bounds overlap): 24 x 6 costs about twice the capsule funnels' step there."""
    wall: Annotated[float, Field(gt=0.0, le=0.02)] = 0.004
    """Target, smooth: panel thickness [m]."""
    scallop: Annotated[float, Field(gt=0.0, le=0.005)] = 1e-3
    """Tool, smooth: largest dip of the sphere stack below the cone [m]."""
    generators: Annotated[int, Field(ge=3, le=32)] = 16
    """Capsules: number of generator capsules."""
    capsule_radius: PosFloat = 0.003

    @property
    def half_angle(self) -> float:
        return math.radians(self.half_angle_deg)


class ToolSettings(StrictModel):
    """Sensor body and funnel tool between the flange and the TCP."""

    sensor_mass: PosFloat = 0.0917
    """Mini45 mass [kg] (ATI catalogue figure, not in the fact sheet)."""
    sensor_height: PosFloat = 0.0157
    sensor_radius: PosFloat = 0.0225
    mass: PosFloat = 0.25
    """Tool (adapter + funnel) mass behind the sensing element [kg]; an estimate."""
    funnel: FunnelGeometry = FunnelGeometry(
        half_angle_deg=30.0, depth=0.045, opening=0.032, generators=8, capsule_radius=0.003
    )
    nose_radius: PosFloat = 0.006
    shaft_length: NonNeg = 0.03
    """Adapter length between sensor and the funnel base [m]."""


class FtSensorSettings(StrictModel):
    """ATI Mini45 with the SI-145-5 calibration (fact sheet sec. 3)."""

    rate: PosFloat = 1000.0
    """Sample rate [Hz]; its period must be a multiple of the physics step."""
    range: Floats6 = (145.0, 145.0, 290.0, 5.0, 5.0, 5.0)
    """Saturation limits in the sensor frame [N, N m]."""
    resolution: Floats2 = (1.0 / 16.0, 1.0 / 752.0)
    """Quantisation step [N, N m]."""
    noise_std: Floats2 = (0.03, 0.0005)
    """White noise per sample [N, N m] (an assumption: half a count on force)."""
    bias_std: Floats2 = (0.5, 0.01)
    """Standard deviation of the random start-up bias [N, N m]."""
    drift_density: Floats2 = (0.002, 2e-5)
    """Random-walk drift density [N/sqrt(s), N m/sqrt(s)]."""
    delay_s: Annotated[float, Field(ge=0.0, le=0.1)] = 0.001
    """Age of a sample's wrench when it is stamped [s], rounded to whole samples:
    the Net F/T's conversion and output path (and its low-pass filter, if one is
    set). 1 ms: one sample period at the paper's 1 kHz with no filter (an
    assumption; the filter settings' delays: drivers/world/NOTES.md)."""


class ContactSettings(StrictModel):
    """Funnel-funnel contact. See :func:`drivers.world.contact.configure_contact` for
    the conversion to solref."""

    stiffness: PosFloat = 2.0e4
    """Quasi-static stiffness of one contact [N/m]."""
    restitution: Annotated[float, Field(ge=0.001, le=0.99)] = 0.5
    """Coefficient of restitution of an impact of the funnels (relative normal
    speed after over before); the contact's damping follows from it
    (:func:`~drivers.description.impact.damping_ratio_for`). 0 is a perfectly inelastic
    contact; the range for plausible funnel materials: drivers/world/NOTES.md."""
    friction: Annotated[float, Field(ge=0.0, le=2.0)] = 0.3
    """Coulomb coefficient between the funnels."""
    impedance: Annotated[float, Field(gt=0.0, lt=1.0)] = 0.8
    """MuJoCo solimp d (constant). In an impact one contact is a spring of
    ``1 - d`` times the quasi-static stiffness (MuJoCo's soft contact makes the
    relative motion ``1 / (1 - d)`` times heavier); an impact that engages several
    contacts at once has a damping ratio within ``d**(-1/4)`` of the one
    ``restitution`` asks for (:func:`~drivers.world.contact.configure_contact`):
    6 % at 0.8 (rebounds within 10 %, measured: tests/test_sim_restitution.py),
    19 % at 0.5."""


#: The paper's friction test: a target set gliding by an impulse showed no deceleration
#: the camera could resolve, "an upper bound of 0.01 for the friction coefficient":
#: every force that slows the gliding target together stays below 0.01 g per unit mass.
IMPULSE_TEST_MU_BOUND = 0.01
#: The glide the test saw (not given in the paper; an assumption, docs/fidelity.md):
#: 10 cm from where the target rests, at 5 cm/s.
IMPULSE_TEST_GLIDE_M = 0.10
IMPULSE_TEST_SPEED_MPS = 0.05


def inertia_tensor(mass_kg: float, size_m: tuple[float, ...],
                   inertia: tuple[float, ...] | None) -> NDArray[np.float64]:
    """The 3x3 inertia tensor about the centre of mass [kg m^2]: ``inertia``
    (``[ixx, iyy, izz, ixy, ixz, iyz]``) when given, else a uniform box of ``size_m``."""
    if inertia is None:
        sx, sy, sz = size_m
        return np.diag([mass_kg * (sy**2 + sz**2) / 12.0, mass_kg * (sx**2 + sz**2) / 12.0,
                        mass_kg * (sx**2 + sy**2) / 12.0])
    ixx, iyy, izz, ixy, ixz, iyz = inertia
    return np.array([[ixx, ixy, ixz], [ixy, iyy, iyz], [ixz, iyz, izz]])


class HoseSettings(StrictModel):
    """The air hose: a linear spring to where the target was placed and a drag, in the bed plane.

    The paper names "the rigidity of the air hose" one of its air bed's two
    limiting factors but gives no number; its own friction test bounds it
    (docs/fidelity.md, "The target's restraint"): a target gliding
    :data:`IMPULSE_TEST_GLIDE_M` from rest at :data:`IMPULSE_TEST_SPEED_MPS`
    decelerated by less than 0.01 g, so ``stiffness * glide + damping * speed +
    mu m g <= 0.01 m g`` (:meth:`TargetSettings.impulse_test_deceleration`).
    The defaults are a weak hose well inside that bound.
    """

    stiffness: NonNeg = 0.25
    """[N/m]; 0 disables the spring (a free target)."""
    damping: NonNeg = 0.1
    """[N s/m]; 0 disables the drag."""


class TargetSettings(StrictModel):
    """The target, placed relative to the start TCF: by default the paper's 12 kg
    aluminium block on the air bed.

    ``support`` says what carries it: ``"air_bed"`` (the paper's: planar motion on the
    glass, bed friction ``mu`` and the ``hose``; it moves along x, y and turns about
    the vertical) or ``"free"`` (nothing: a free body in six degrees of freedom, as in
    orbit; it is weightless whatever ``physics.gravity``, which then loads only the
    arm and its tool, as in a ground facility, and ``mu``/``hose`` do not apply).
    """

    support: Literal["air_bed", "free"] = "air_bed"
    mass: PosFloat = 12.0
    size: Floats3 = (0.25, 0.25, 0.05)
    inertia: Floats6 | None = None
    """Inertia tensor about the centre of mass in the block's frame,
    ``[ixx, iyy, izz, ixy, ixz, iyz]`` [kg m^2]; none: a uniform block of ``size``."""
    mu: Annotated[float, Field(ge=0.0, le=0.02)] = 0.0085
    """Residual bed friction coefficient (air bed). The paper bounds it (< 0.01, camera
    resolution) and its outcomes bound it from below: with the target free,
    below about 0.007 Method II at 0.8 N aligns by pushing the target along
    (measured; the band and the nominal value: docs/fidelity.md)."""
    distance: float = 0.03
    """Gap along TCF Z from the tool tip to the funnel mouth plane at start [m]."""
    lateral: float = 0.012
    """Offset of the funnel axis along TCF Y at start [m]."""
    vertical: float = 0.0
    """Offset of the funnel axis along the world vertical at start [m] (free only)."""
    yaw_deg: float = 8.0
    """Rotation of the target about the vertical (TCF X) at start [deg]."""
    pitch_deg: float = 0.0
    """Tilt of the funnel axis about the block's lateral axis at start [deg] (free only):
    the block turned by yaw about the vertical, then pitch about its own y, then roll."""
    roll_deg: float = 0.0
    """Rotation of the block about its funnel axis at start [deg] (free only)."""
    velocity: Floats3 = (0.0, 0.0, 0.0)
    """Initial twist in the bed plane: [vx, vy] world [m/s], yaw rate [rad/s] (air bed)."""
    drift_mps: Floats3 = (0.0, 0.0, 0.0)
    """Initial velocity of the centre of mass in the world frame [m/s] (free only)."""
    tumble_radps: Floats3 = (0.0, 0.0, 0.0)
    """Initial angular velocity in the world frame [rad/s] (free only)."""
    funnel: FunnelGeometry = FunnelGeometry()
    hose: HoseSettings = HoseSettings()

    @model_validator(mode="after")
    def _check_support(self) -> TargetSettings:
        if self.support == "air_bed":
            for name in ("vertical", "pitch_deg", "roll_deg"):
                if getattr(self, name) != 0.0:
                    raise ValueError(f"target.{name} needs target.support = 'free': the air "
                                     "bed keeps the target level at the funnels' height")
            for name in ("drift_mps", "tumble_radps"):
                if any(getattr(self, name)):
                    raise ValueError(f"target.{name} needs target.support = 'free' (on the "
                                     "air bed: target.velocity = [vx, vy, wz])")
        elif any(self.velocity):
            raise ValueError("target.velocity is the air bed's planar twist; a free target "
                             "starts with target.drift_mps and target.tumble_radps")
        if self.inertia is not None:
            full = self.inertia_matrix()
            eig = np.linalg.eigvalsh(full)
            a, b, c = sorted(eig.tolist())
            if a <= 0.0 or a + b < c * (1.0 - 1e-9):
                raise ValueError(f"target.inertia: principal moments {a:.4g}, {b:.4g}, "
                                 f"{c:.4g} kg m^2 are not a rigid body's (each positive, "
                                 "no one above the sum of the other two)")
        return self

    def inertia_matrix(self) -> NDArray[np.float64]:
        """The 3x3 inertia tensor about the centre of mass, block frame [kg m^2]."""
        return inertia_tensor(self.mass, self.size, self.inertia)

    def impulse_test_deceleration(self, gravity: float = 9.81,
                                  glide_m: float = IMPULSE_TEST_GLIDE_M,
                                  speed_mps: float = IMPULSE_TEST_SPEED_MPS) -> float:
        """The largest deceleration [m/s^2] of this target gliding ``glide_m`` from where
        it rests at ``speed_mps``: bed friction, the hose's spring at the glide's end
        and its drag. The paper's test puts it below ``IMPULSE_TEST_MU_BOUND * gravity``."""
        h = self.hose
        return self.mu * gravity + (h.stiffness * glide_m + h.damping * speed_mps) / self.mass


#: Body names the simulator uses itself (an object may not take them).
RESERVED_BODIES = ("target", "chaser", "world")


class ObjectSettings(StrictModel):
    """A body of the world beside the target, for a scenario of its own (a plate to press,
    a ball to push, a handle to reach): a primitive shape, placed like the target from
    the start TCF, free (weightless, in six degrees of freedom) or fixed to the world.

    The tool touches it with the scene's ``[contact]``; the simulator's truth reports a
    free object by ``name`` (pose, twist, mass) and each of its ``sites`` as the named
    frame ``<name>.<site>``, for the scenario to measure."""

    name: Annotated[str, Field(pattern=r"^[a-z][a-z0-9_]*$")]
    shape: Literal["box", "sphere", "cylinder"] = "box"
    size: Floats3 = (0.1, 0.1, 0.1)
    """box: edges; sphere: diameter (first value); cylinder: diameter, -, length [m]."""
    mass: PosFloat = 1.0
    support: Literal["free", "fixed"] = "free"
    distance: float = 0.1
    """From the tool tip along TCF Z at start to the object's centre [m]."""
    lateral: float = 0.0
    """Along TCF Y at start [m]."""
    vertical: float = 0.0
    """Along the world vertical [m]."""
    drift_mps: Floats3 = (0.0, 0.0, 0.0)
    """Initial velocity, world frame [m/s] (free only)."""
    tumble_radps: Floats3 = (0.0, 0.0, 0.0)
    """Initial angular velocity, world frame [rad/s] (free only)."""
    sites: dict[str, Floats3] = Field(default_factory=dict)
    """Named frames on it, positions in its frame [m] (axes: the world's at start)."""

    @model_validator(mode="after")
    def _check(self) -> ObjectSettings:
        if self.name in RESERVED_BODIES:
            raise ValueError(f"objects: name {self.name!r} is the simulator's own; "
                             "pick another")
        if self.support == "fixed" and (any(self.drift_mps) or any(self.tumble_radps)):
            raise ValueError(f"objects.{self.name}: a fixed object cannot drift or tumble")
        used = {"box": self.size, "sphere": self.size[:1], "cylinder": self.size[::2]}
        if any(size <= 0.0 for size in used[self.shape]):  # the values its shape uses
            raise ValueError(f"objects.{self.name}.size must be positive")
        return self


class BaseSettings(StrictModel):
    """What the arm stands on: the ground (``"fixed"``) or a spacecraft that floats.

    A floating base is a free body (the chaser) with the arm on its top face at
    ``arm.base_pos``; the arm's controller and ffexp's loop work in the arm's base
    frame, which moves with it, as on a real servicer. Its modes:

    * ``free_floating``: no actuation; the momentum of base, arm and target together
      is conserved (Umetani and Yoshida's free-floating regime);
    * ``attitude_held``: a PD on the base's attitude, each body axis' torque limited as
      reaction wheels limit it (the position floats);
    * ``pose_held``: PDs on attitude and position, forces limited as thrusters limit
      them (a free-flying base).

    The wrenches are computed once per control cycle and held (a spacecraft's attitude
    loop runs at about the arm's rate or slower). Needs ``physics.gravity = 0``.
    The defaults are assumptions of the small-satellite class, not one servicer's
    data: 150 kg, a 0.6 m cube (for scale: ETS-VII, the first free-floating space
    robot, was a 2500 kg satellite with a 2 m arm; National Academies, "Assessment
    of Options for Extending the Life of the Hubble Space Telescope", 2005, p. 129).
    """

    mode: Literal["fixed", "free_floating", "attitude_held", "pose_held"] = "fixed"
    mass: PosFloat = 150.0
    """[kg]"""
    size: Floats3 = (0.6, 0.6, 0.6)
    """Edges of the base's box [m] (its inertia, unless ``inertia`` is given, and its drawing)."""
    inertia: Floats6 | None = None
    """``[ixx, iyy, izz, ixy, ixz, iyz]`` about its centre of mass [kg m^2]; none: a
    uniform box of ``size``."""
    attitude_kp: NonNeg = 2.25
    """[N m/rad]: 0.5 rad/s of bandwidth on the default 9 kg m^2 (an assumption)."""
    attitude_kd: NonNeg = 6.3
    """[N m s/rad]: damping ratio 0.7 at that bandwidth."""
    torque_limit: PosFloat = 0.1
    """Largest torque per body axis [N m] (reaction wheels of the small-satellite class;
    an assumption)."""
    position_kp: NonNeg = 6.0
    """[N/m] (pose_held): 0.2 rad/s on 150 kg."""
    position_kd: NonNeg = 42.0
    """[N s/m] (pose_held): damping ratio 0.7."""
    force_limit: PosFloat = 1.0
    """Largest force per body axis [N] (pose_held: 1 N class cold-gas thrusters; an
    assumption)."""

    def inertia_matrix(self) -> NDArray[np.float64]:
        """The 3x3 inertia tensor about the centre of mass [kg m^2]."""
        return inertia_tensor(self.mass, self.size, self.inertia)

    @property
    def floating(self) -> bool:
        return self.mode != "fixed"


class Scene(StrictModel):
    """A whole simulated rig."""

    name: str = "paper"
    seed: int = 0
    physics: PhysicsSettings = PhysicsSettings()
    fri: FriTiming = FriTiming()
    controller: ControllerSettings = ControllerSettings()
    arm: ArmSettings = ArmSettings()
    tool: ToolSettings = ToolSettings()
    ft_sensor: FtSensorSettings = FtSensorSettings()
    contact: ContactSettings = ContactSettings()
    target: TargetSettings = TargetSettings()
    base: BaseSettings = BaseSettings()
    carrier: CarrierSettings = CarrierSettings()
    """A second robot rendering the target's free flight (``docs/hil.md``)."""
    objects: list[ObjectSettings] = Field(default_factory=list)
    """Further bodies of the world (``[[objects]]``), for scenarios of their own."""

    @model_validator(mode="after")
    def _check_rates(self) -> Scene:
        dt = self.physics.timestep
        n = self.fri.cycle / dt
        if abs(n - round(n)) > 1e-6:
            raise ValueError(
                f"fri.cycle {self.fri.cycle} is not a multiple of physics.timestep {dt}"
            )
        k = (1.0 / self.ft_sensor.rate) / dt
        if abs(k - round(k)) > 1e-6 or round(k) < 1:
            raise ValueError(f"ft_sensor.rate {self.ft_sensor.rate} Hz: period is not a multiple "
                             f"of physics.timestep {dt}")
        if self.target.support == "air_bed" and self.physics.gravity == 0.0:
            raise ValueError("physics.gravity = 0 needs target.support = 'free': the air "
                             "bed carries the target on its pads by its weight")
        if self.base.floating and self.physics.gravity != 0.0:
            raise ValueError(f"base.mode {self.base.mode!r} needs physics.gravity = 0: a "
                             "floating base is a spacecraft in orbit")
        names = [o.name for o in self.objects]
        twice = sorted({n for n in names if names.count(n) > 1})
        if twice:
            raise ValueError(f"objects: {', '.join(twice)} named twice")
        if self.base.floating and self.target.support != "free":
            raise ValueError(f"base.mode {self.base.mode!r} needs target.support = 'free'")
        tool = self.tool.funnel
        if tool.opening >= self.target.funnel.opening:
            raise ValueError("tool.funnel.opening must be smaller than target.funnel.opening")
        for name, val in zip("xyz", self.controller.cart_stiffness[:3], strict=True):
            if not 0.0 <= val <= self.controller.cart_stiffness_max[0]:
                raise ValueError(f"controller.cart_stiffness {name} outside [0, max]")
        for name, val in zip(("rx", "ry", "rz"), self.controller.cart_stiffness[3:], strict=True):
            if not 0.0 <= val <= self.controller.cart_stiffness_max[1]:
                raise ValueError(f"controller.cart_stiffness {name} outside [0, max]")
        if any(not 0.0 <= v <= 1.0 for v in self.controller.cart_damping):
            raise ValueError("controller.cart_damping must lie in [0, 1]")
        return self

    @property
    def substeps(self) -> int:
        """Physics steps per FRI cycle."""
        return round(self.fri.cycle / self.physics.timestep)

    @property
    def ft_decimation(self) -> int:
        """Physics steps per F/T sample."""
        return round(1.0 / self.ft_sensor.rate / self.physics.timestep)


def load_scene(path: Path, overrides: Iterable[str] = ()) -> Scene:
    """Read a scene TOML file (with ``dotted.key=value`` overrides)."""
    return load_model(Scene, path, overrides)
