"""The world's state at the end of a cycle, built when first read.

:class:`LazyArmState` is the :class:`~drivers.world.arm.ArmState` that
:attr:`SimWorld.last_state <drivers.world.world.SimWorld.last_state>` returns.
Its fields (the joints, ``tcp_pose_m``, the set-points in use, ``warning``, the
Jacobian, mass matrix, joint torques, external wrench, ``gravity_nm`` and the
``truth``) are computed from the world's MuJoCo data on the first read of any of
them, all at once by :class:`StateFill` (one compiled call,
:func:`drivers.world.kernels.fill_state`, into two buffers the fields are views of,
allocated for 32 states at a time (``_BLOCK``); the products of the torques and the
TCP twist stay numpy's BLAS calls).

A cycle nobody reads costs no measurement. The values are those of the cycle the
state belongs to: before the world changes its data (the next cycle, a new target
velocity) it calls :meth:`LazyArmState.resolve` on a state that is still
referenced, which computes them if nobody read them yet. Copies and pickles are
plain :class:`ArmState` objects with every field.
"""

from __future__ import annotations

import dataclasses
from typing import TYPE_CHECKING, Any

import numpy as np

from drivers.base.types import BodyTruth, GroundTruth
from drivers.world.arm import ArmMode, ArmState, ArmWarning

if TYPE_CHECKING:
    from drivers.world.world import SimWorld

__all__ = ["LazyArmState", "StateFill"]

_WARN_TORQUE = int(ArmWarning.TORQUE_LIMIT)
_WARN_VELOCITY = int(ArmWarning.VELOCITY_LIMIT)
_WARN_POSITION = int(ArmWarning.POSITION_LIMIT)
_FIELDS = tuple(f.name for f in dataclasses.fields(ArmState))
_WARN_BITS = np.array((_WARN_VELOCITY, _WARN_POSITION, _WARN_TORQUE))
#: ArmWarning(bits) for every combination of the 4 bits (the same objects; a lookup
#: is cheaper than the enum's constructor)
_ARM_WARNINGS = tuple(
    ArmWarning(bits) for bits in range(1 << max(int(w) for w in ArmWarning).bit_length()))
_NO_POSE = np.zeros((0, 4))  # fill_state's tcp_src: the TCP's pose from its site
_TOPIC_PREFIX: str = GroundTruth().topic_prefix  # the simulator's recording topics
_new = object.__new__
#: States whose buffers are allocated at once (a state's arrays: views of one block).
_BLOCK = 32


class LazyArmState(ArmState):
    """An :class:`ArmState` of ``world``'s current cycle whose arrays are computed on
    first read (module docstring). ``cycle``, ``time_ns`` and ``mode`` are set now."""

    def __init__(self, world: SimWorld) -> None:  # not ArmState's: no field is built here
        self.cycle = world.cycle
        self.time_ns = world.cycle * world.cycle_ns
        self.mode = world.mode
        self._world: SimWorld | None = world

    def __getattr__(self, name: str) -> Any:
        # only for attributes not set yet: the fields, before the fill
        world = self.__dict__.get("_world")
        if name not in _LAZY or world is None:
            raise AttributeError(f"{type(self).__name__!r} object has no attribute {name!r}")
        self.resolve()
        return self.__dict__[name]

    # ``warning`` has a class default in ArmState, so it cannot go through __getattr__
    @property
    def warning(self) -> ArmWarning:
        if "warning" not in self.__dict__:
            if self.__dict__.get("_world") is None:
                return ArmWarning.NONE
            self.resolve()
        value: ArmWarning = self.__dict__["warning"]
        return value

    @warning.setter
    def warning(self, value: ArmWarning) -> None:
        self.__dict__["warning"] = value

    def resolve(self) -> None:
        """Compute every field, now (the world is about to change); a field already set
        keeps its value."""
        world = self.__dict__.get("_world")
        if world is None:
            return
        world._fill(self, world)
        self._world = None

    def __reduce__(self) -> tuple[Any, ...]:
        # copies and pickles: a plain ArmState with every field
        return (ArmState, (), {name: getattr(self, name) for name in _FIELDS})


#: The fields a :class:`LazyArmState` computes (the others are set when it is made).
_LAZY = frozenset(_FIELDS) - {"cycle", "time_ns", "mode"}
#: A state's own attributes before its fill (``cycle``, ``time_ns``, ``mode``, ``_world``).
_OWN = 4


class StateFill:
    """Fills a :class:`LazyArmState` of ``world`` (``fill(state, world)``): the layout of
    its buffers and the compiled call's arguments that stay the same every cycle.

    ``mats`` (:func:`~drivers.world.kernels.fill_state`): mass matrix, Jacobian, the
    vectors (joints, joint set-point, gravity, contact), the body twists; ``poses``:
    TCP, Cartesian set-point, bodies, sites (the funnel's mouth, the TCP in the world
    with a floating base, the objects' frames). Each field is one index of them.
    """

    def __init__(self, w: SimWorld) -> None:
        from drivers.world import kernels  # numba: imported when a world is built

        d = w.data
        self._n = n = w._n
        self._kernel, self._torques = kernels.fill_state, kernels.torques
        # the buffers of _BLOCK states at once (a state's are one index of them)
        self._at = _BLOCK
        self._mats_block = self._poses_block = np.zeros((0, 0))
        self._bodies = tuple((name, bid, 3 + k)
                             for k, (name, bid, _, _) in enumerate(w.bodies._rows))
        self._body_masses = w.bodies
        self._masses_of: object = None
        self._masses: list[float] = []
        sites = [("funnel_mouth", w._mouth)]
        if w.chaser is not None:  # the TCP in the world (the state's is in the base's)
            sites.append(("tcp", w._tcp))
        sites += w._object_sites
        self._site_names = tuple(name for name, _ in sites)
        side = max(n, 6)
        self._shape = (3 + len(self._bodies), side, side)
        self._square = side == n  # the Jacobian's and mass matrix's rows contiguous
        self._npose = kernels.POSE_BODIES + len(self._bodies) + len(sites)
        self._site0 = kernels.POSE_BODIES + len(self._bodies)
        # the compiled call's arrays by their addresses (kept here: they live as long)
        self._arrays = (w._qpos_arm, w._qvel_arm, w._actuator_arm, w._gravcomp_arm,
                        d.site_xpos, d.site_xmat, d.xpos, d.xmat, w._jac2, w._jfull2,
                        w._mfull, np.zeros(6), w._warn_limits)
        assert len(self._arrays) == len(kernels.FILL_ARRAYS)
        for a in self._arrays:
            if a.dtype != np.float64 or not a.flags.c_contiguous:
                raise ValueError("fill_state's arrays: C-contiguous float64")
        m = w.model
        dims = (n, m.nv, m.nsite, m.nbody, w._tcp, w._va.start, len(self._bodies), len(sites),
                *_WARN_BITS.tolist())
        assert len(dims) == len(kernels.FILL_DIMS)
        fns, ma, da = w._mj
        self._args = (fns, ma, da, np.array([a.ctypes.data for a in self._arrays],
                                            dtype=np.int64),
                      np.array([*dims, *(bid for _, bid, _ in self._bodies),
                                *(sid for _, sid in sites)], dtype=np.int64))

    def __call__(self, s: LazyArmState, w: SimWorld) -> None:
        at = self._at
        if at == _BLOCK:
            self._mats_block = np.empty((_BLOCK, *self._shape))
            self._poses_block = np.empty((_BLOCK, self._npose, 4, 4))
            at = 0
        self._at = at + 1
        mats = self._mats_block[at]
        poses = self._poses_block[at]
        chaser = w.chaser
        cart = s.mode == ArmMode.CART_IMPEDANCE
        warning = self._kernel(*self._args, not w._kin_ok, not w._m_ok, w._jnt_pos, cart,
                               w._cart_pos, _NO_POSE if chaser is None else w.tcp_pose,
                               w._contact, mats, poses)
        w._kin_ok = w._m_ok = True
        tcp = poses[0]
        if chaser is None:  # the world's TCP pose of this state: the state's
            w._tcp_pose = tcp
            w._pose_ok = True
        n = self._n
        if self._square:
            mass, jac = mats[0], mats[1, :6]
        else:  # fewer than 6 joints: contiguous copies
            mass, jac = mats[0, :n, :n].copy(), mats[1, :6, :n].copy()
        contact = w._contact
        # (``a.dot(b)``: numpy's ``@`` of them, the same BLAS call without the ufunc's
        # overhead; tests/test_world_fill.py)
        tau_ext = contact.dot(jac)  # J^T w
        # Link-side torque sensors: M qdd + c + g = tau_msr + tau_ext.
        tau_msr = mass.dot(w._qacc_arm)
        self._torques(tau_msr, w._bias_arm, tau_ext)  # += bias, -= tau_ext (compiled)
        # the truth's objects without their dataclasses' __init__ (the same fields in
        # the same order as truth.ground_truth's)
        masses = self._body_masses._mass
        if masses is not self._masses_of:  # (a body's mass reported otherwise: another)
            self._masses_of = masses
            self._masses = [float(masses[bid]) for _, bid, _ in self._bodies]
        bodies = {}
        k = 2  # (indexing: cheaper than iterating over the array)
        for (name, _, at), mass_kg in zip(self._bodies, self._masses, strict=True):
            body = bodies[name] = _new(BodyTruth)
            body.__dict__ = {"pose": poses[k], "twist": mats[at, 0, :6], "mass_kg": mass_kg}
            k += 1
        sites = {}
        for name in self._site_names:
            sites[name] = poses[k]
            k += 1
        vecs = mats[2]
        d = s.__dict__
        old = d.copy() if len(d) > _OWN else None
        d["jnt_pos_rad"] = vecs[0, :n]
        d["tcp_pose_m"] = tcp
        d["cmd_jnt_pos_rad"] = vecs[1, :n]
        d["cmd_cart_pose_m"] = poses[1]
        d["warning"] = _ARM_WARNINGS[w._warning | warning]
        d["jacobian"] = jac
        d["mass_matrix"] = mass
        d["ext_jnt_trq_nm"] = tau_ext
        d["jnt_trq_nm"] = tau_msr
        d["ext_wrench_n_nm"] = vecs[3, :6]
        d["gravity_nm"] = vecs[2, :n]
        truth = d["truth"] = _new(GroundTruth)
        truth.__dict__ = {
            "bodies": bodies, "sites": sites, "attached": w._attached,
            "contact_wrench": contact, "in_contact": w._touching,
            "tcp_twist": jac.dot(w._qvel_arm),
            "base_pose": None if chaser is None else chaser.arm_base_pose(),
            "topic_prefix": _TOPIC_PREFIX}
        if old is not None:  # fields set before the fill keep their values
            d.update(old)
