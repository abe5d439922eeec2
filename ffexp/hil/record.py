"""Run an impact protocol on the simulated carrier and record it: one MCAP file with the
carrier's loop (``/carrier/state``), the same impact on the ideal free body
(``/hil/ideal``, for the target's true restitution and the rendered path's error), the
contact's truth (``/hil/contact``), the device that stopped the run and why
(``/carrier/event``), the scene as run and the impact's numbers (``hil_impact``
metadata). :func:`ffexp.hil.analysis.analyze_recording` reads it back."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from mcap.writer import CompressionType, Writer

from drivers import registry
from drivers.base.topics import CDR_HEADER, CdrTopic, JsonTopic
from drivers.base.types import F64
from drivers.carrier.armbench import run_arm_impact
from drivers.carrier.bench import Impact, ImpactTrace, run_impact
from drivers.carrier.plant import JointLink, JointReading, WirePlant, arm_layout
from drivers.carrier.topics import CARRIER_EVENT, CARRIER_STATE, HIL_CONTACT, HIL_IDEAL
from drivers.description.scene import Scene, load_scene
from ffexp.errors import InputError
from ffexp.hil.protocol import HilProtocol

__all__ = ["HIL_METADATA", "HilRun", "record_impact", "render_impact", "run_protocol"]

#: The metadata record that marks a recording as a rendered-target impact.
HIL_METADATA = "hil_impact"


@dataclass(frozen=True)
class HilRun:
    """One impact: the scene as run, the rendered and the ideal trace."""

    scene: Scene
    protocol: HilProtocol
    rendered: ImpactTrace
    ideal: ImpactTrace


def _impact(protocol: HilProtocol, *, render: bool) -> Impact:
    im, faults = protocol.impact, protocol.faults
    return Impact(speed_mps=im.speed_mps, gap_m=im.gap_m, offset_m=im.offset_m,
                  after_s=im.after_s, duration_s=im.duration_s, render=render,
                  ft_stale_at_s=faults.ft_stale_at_s if render else None,
                  link_lost_at_s=faults.link_lost_at_s if render else None)


def run_protocol(protocol: HilProtocol, scene_overrides: tuple[str, ...] = (),
                 scene: Scene | None = None) -> HilRun:
    """Run the protocol's impact rendered by the carrier (in process, or over the wire
    with its ``[link]``) and on the ideal free body."""
    if scene is None:
        scene = load_scene(protocol.scene, (*protocol.scene_set, *scene_overrides))
    impact = _impact(protocol, render=True)
    if protocol.link is not None:
        rendered = _over_the_wire(scene, impact, protocol)
    else:
        rendered = render_impact(scene, impact, protocol.seed)
    ideal = run_impact(scene, _impact(protocol, render=False), seed=protocol.seed)
    return HilRun(scene, protocol, rendered, ideal)


def render_impact(scene: Scene, impact: Impact, seed: int = 0) -> ImpactTrace:
    """The impact on the carrier the scene's ``carrier.model`` names: its interpolator, or
    its arm in the two-arm world (in process)."""
    if scene.carrier.model == "interpolator":
        return run_impact(scene, impact, seed=seed)
    layout = arm_layout(scene, impact.gap_m, impact.offset_m)
    return run_arm_impact(scene, impact, layout, registry.carrier_world(scene, layout, seed))


class _Killed:
    """The carrier's link, whose emulator is killed at the first reading from ``at_s`` on
    (the fault ``faults.carrier_emulator_killed_at_s``)."""

    def __init__(self, link: JointLink, at_s: float, kill: Callable[[], None]) -> None:
        self.link, self.at_s = link, at_s
        self._kill: Callable[[], None] | None = kill
        self.name = link.name

    def read(self) -> JointReading:
        reading = self.link.read()
        if self._kill is not None and reading.t_s >= self.at_s - 1e-12:
            self._kill()
            self._kill = None
        return reading

    def send(self, q: F64, qd: F64) -> None:
        self.link.send(q, qd)

    def close(self) -> None:
        self.link.close()


def _over_the_wire(scene: Scene, impact: Impact, protocol: HilProtocol) -> ImpactTrace:
    """Both arms served, each by its emulator, on one world; the run over their links."""
    link = protocol.link
    assert link is not None
    if scene.carrier.model != "arm":
        raise InputError(f"{protocol.name}: link: runs over the wire need the carrier as an "
                         f"arm (carrier.model = 'arm'), the scene has {scene.carrier.model!r}")
    for role, dev in (("chaser", link.chaser), ("carrier", link.carrier)):
        try:
            entry = registry.emulator(dev.emulator)
        except KeyError:
            names = ", ".join(e.name for e in registry.emulators())
            raise InputError(f"{protocol.name}: link.{role}.emulator: {dev.emulator!r}: choose "
                             f"one of {names}") from None
        if entry.serve_joint is None or entry.joint_link is None:
            raise InputError(f"{protocol.name}: link.{role}.emulator: {dev.emulator!r} serves "
                             "no arm of a shared world")
    layout = arm_layout(scene, impact.gap_m, impact.offset_m)
    with registry.serve_two_arms(
            scene, layout, chaser=(link.chaser.emulator, link.chaser.host, link.chaser.port),
            carrier=(link.carrier.emulator, link.carrier.host, link.carrier.port),
            seed=protocol.seed) as servers:
        host, port = servers.address("carrier")
        carrier: JointLink = registry.joint_link(link.carrier.emulator, "carrier", host, port,
                                                 layout.carrier.arm.joints)
        host, port = servers.address("chaser")
        chaser: JointLink = registry.joint_link(link.chaser.emulator, "chaser", host, port,
                                                layout.chaser.arm.joints)
        killed_at = protocol.faults.carrier_emulator_killed_at_s
        if killed_at is not None:
            carrier = _Killed(carrier, killed_at, lambda: servers.kill("carrier"))
        plant = WirePlant(carrier, chaser, servers.world.drain_truth)
        return run_arm_impact(scene, impact, layout, plant)


def _cdr(topic: CdrTopic, rows: list[tuple[float, ...]]) -> list[bytes]:
    spec = topic.spec
    rec = np.zeros(len(rows), dtype=spec.dtype)
    rec["_cdr_header"] = np.frombuffer(CDR_HEADER, dtype="V4")[0]
    table = np.asarray(rows, dtype=np.float64).reshape(len(rows), -1)
    col = 0
    for f in spec.fields:
        rec[f.name] = table[:, col] if f.count == 1 else table[:, col:col + f.count]
        col += f.count
    return [r.tobytes() for r in rec]


def record_impact(run: HilRun, path: Path) -> Path:
    """Write the run's recording to ``path`` (its folder is made).

    Raises:
        InputError: the file cannot be created.
    """
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fh = path.open("xb")
    except OSError as exc:
        raise InputError(f"{path}: cannot create recording: {exc.strerror}") from None
    with fh:
        w = Writer(fh, compression=CompressionType.ZSTD)
        w.start(profile="", library="ffexp")
        channels: dict[str, int] = {}
        for topic in (CARRIER_STATE, HIL_IDEAL, HIL_CONTACT):
            sid = w.register_schema(topic.spec.name, "ros2msg", topic.spec.ros2msg.encode())
            channels[topic.topic] = w.register_channel(topic.topic, "cdr", sid)
        ev: JsonTopic = CARRIER_EVENT
        sid = w.register_schema(ev.schema_name, "jsonschema", ev.schema_bytes)
        channels[ev.topic] = w.register_channel(ev.topic, "json", sid)
        cycle = run.scene.carrier.cycle_s
        series = (
            (CARRIER_STATE, run.rendered.cycle_t_s, run.rendered.cycle),
            (HIL_IDEAL, run.ideal.cycle_t_s, run.ideal.cycle),
            (HIL_CONTACT, run.rendered.fine_t_s, run.rendered.fine),
        )
        for topic, times, rows in series:
            cid = channels[topic.topic]
            for seq, (t, data) in enumerate(zip(times, _cdr(topic, rows), strict=True)):
                ns = round(t * 1e9)
                w.add_message(cid, log_time=ns, data=data, publish_time=ns, sequence=seq)
        hold = run.rendered.hold
        if hold is not None:
            ns = round(hold.t_s * 1e9)
            for seq, (device, cause) in enumerate(((hold.device, hold.cause),
                                                   ("chaser", f"stopped: {hold.device} held"))):
                w.add_message(channels[ev.topic], log_time=ns, publish_time=ns, sequence=seq,
                              data=json.dumps({"device": device, "cause": cause,
                                               "t_s": hold.t_s}).encode())
        r = run.rendered
        w.add_metadata(HIL_METADATA, {
            "protocol": run.protocol.name,
            "effective_mass_kg": repr(r.effective_mass_kg),
            "contact_stiffness_npm": repr(r.stiffness_npm),
            "contact_damping_nspm": repr(r.damping_nspm),
            "speed_mps": repr(run.protocol.impact.speed_mps),
            "carrier_cycle_s": repr(cycle),
            "extra_delay_cycles": str(run.scene.carrier.extra_delay_cycles),
            "compensation": run.scene.carrier.compensation,
            "carrier_model": run.scene.carrier.model,
        })
        w.add_metadata("scene", {"scene_json": run.scene.model_dump_json()})
        w.finish()  # type: ignore[no-untyped-call]
    return path

