"""The scene's ``[carrier]`` table: a second robot that carries the target's mock-up behind
its own F/T sensor and renders the target's free-floating dynamics (a micro-gravity
emulator, as DLR's EPOS and OOS-SIM). Its loop, delay, integrator, compensation and
safety limits; what the loop does with them is :mod:`drivers.carrier`.

Every delay of the loop adds to the energy an impact gains: the F/T sensor's
(``ft_sensor.delay_s`` and its sample period), the carrier's cycle (the force is held
over it), its response (``response_cycles``) and any ``extra_delay_cycles``
(``docs/hil.md``).
"""

from __future__ import annotations

from typing import Annotated, Literal

from pydantic import Field

from drivers.config import StrictModel

__all__ = ["CarrierSettings"]


class CarrierSettings(StrictModel):
    """The carrier robot's rendering loop (used when a run renders the target)."""

    model: Literal["interpolator", "arm"] = Field(
        "interpolator", description="How the carrier is simulated: 'interpolator' (its "
        "set-points followed along a cubic, response_cycles late, the contact a point on an "
        "ideal flange) or 'arm' (a position-controlled arm in one MuJoCo world with the "
        "chaser's arm, the mock-up behind a simulated F/T sensor on its flange, each "
        "set-point through inverse kinematics to joint targets as servoJ; docs/hil.md).")
    arm: Literal["ur5e", "lwr4", "fr3"] = Field(
        "ur5e", description="The carrier's arm with model = 'arm' (a name of the scene's "
        "arm models).")
    render_target: bool = Field(
        False, description="In the simulator's world (ffexp run, campaign, sweep): the free "
        "target is the carrier's mock-up (carrier.mockup_mass_kg, the target's shape and "
        "funnel) held by a servo to the pose the carrier loop renders from the contact's "
        "wrench, instead of a free body (needs target.support = 'free'; docs/hil.md).")
    servo_bandwidth_hz: Annotated[float, Field(gt=0.0, le=200.0)] = Field(
        25.0, description="The carrier arm's joint position servo: each joint's natural "
        "frequency with its own inertia at the start pose [Hz] (not published by UR: our "
        "assumption; the torques are clipped at the arm's published limits).")
    servo_damping_ratio: Annotated[float, Field(gt=0.0, le=5.0)] = Field(
        1.0, description="The joint servo's damping ratio.")

    cycle_s: Annotated[float, Field(ge=0.0005, le=0.05)] = Field(
        0.002, description="The carrier's control cycle [s] (a UR e-series' 500 Hz: 2 ms; "
        "EPOS commands at 250 Hz). A multiple of physics.timestep.")
    extra_delay_cycles: Annotated[int, Field(ge=0, le=100)] = Field(
        0, description="Whole cycles the measured wrench waits before the integrator uses it "
        "(a transport delay; the sweep's knob).")
    response_cycles: Annotated[int, Field(ge=0, le=20)] = Field(
        1, description="Cycles after the one a set-point is sent in before the carrier's "
        "interpolator starts towards it (it then reaches it one cycle later).")
    integrator: Literal["symplectic", "explicit"] = Field(
        "symplectic", description="The free body's integrator per cycle: semi-implicit "
        "(symplectic) Euler adds no energy; explicit Euler acts as one more cycle of delay.")
    compensation: Literal["none", "passivity", "compliance"] = Field(
        "none", description="none; passivity: a time-domain passivity observer and controller "
        "on the rendered target's port (Ryu and Hannaford); compliance: a virtual spring "
        "between the rendered body and the mock-up (EPOS).")
    compliance_stiffness_npm: Annotated[float, Field(gt=0.0)] | None = Field(
        None, description="The virtual spring of compensation = 'compliance' [N/m] "
        "(default: twice contact.stiffness: a delayed spring stiffer than the contact's "
        "keeps the loop's small-gain margin at any delay).")
    mockup_mass_kg: Annotated[float, Field(ge=0.0)] = Field(
        2.0, description="The mock-up's mass outboard of the carrier's F/T sensor [kg]: its "
        "weight and inertia are in every reading and are compensated.")
    lab_gravity_mps2: Annotated[float, Field(ge=0.0)] = Field(
        9.81, description="Gravity in the lab, acting on the mock-up (the rendered target is "
        "weightless whatever physics.gravity says).")
    workspace_m: tuple[float, float, float] = Field(
        (0.5, 0.5, 0.5), description="Half-extents of the box about the start pose the "
        "flange must stay in [m].")
    speed_limit_mps: Annotated[float, Field(gt=0.0)] = Field(
        0.5, description="Largest commanded flange speed [m/s].")
    force_limit_n: Annotated[float, Field(gt=0.0)] = Field(
        300.0, description="Largest force the carrier's F/T sensor may read [N].")
    ft_stale_s: Annotated[float, Field(gt=0.0)] = Field(
        0.01, description="Age of the newest F/T sample beyond which the carrier holds [s].")
    energy_gain_limit: Annotated[float, Field(ge=0.0)] = Field(
        0.01, description="The loop is unstable (the carrier holds) when, in a contact, the "
        "rendered target's kinetic energy relative to the held chaser exceeds the energy it "
        "came in with by this fraction: a passive contact cannot give it more.")
