"""``ffexp emulate``: a simulated robot controller (``--robot``) and Net F/T box.

The controller side of the link, wrapping the MuJoCo rig. The default, a KRC2
LR, sends FRI measurement packets to ``--remote`` every cycle and steps the
world with the commands that come back (see :mod:`drivers.fri.emulate.server`),
and serves the simulated Mini45 as an ATI Net F/T box on ``--netft-port``;
another controller (a UR over RTDE) listens on ``--listen``. The robots and
their defaults are the families' entries (:mod:`drivers.emulate.robots`); a
controller's own faults are ``--fault NAME=VALUE``. This command parses
its options into settings and reports; the rig is assembled and served by
:class:`drivers.emulate.session.EmulatedRig`.

It serves until ``--duration`` of simulated time or a SIGINT/SIGTERM (then
the current cycle ends, the counters are printed and the exit code is 0: a
signal is how an emulator is meant to end); a second signal gives up at
once (exit 130).
"""

from __future__ import annotations

import sys
from contextlib import nullcontext
from pathlib import Path

import typer

from drivers.emulate import robots
from ffexp.cli._common import (
    StopFlag,
    check_cpus,
    check_scene_file,
    cli_errors,
    positive,
    stop_signals,
)
from ffexp.errors import ConfigError

_ROBOTS = tuple(robots.robot(n) for n in robots.robot_names())
ROBOT_HELP = "The emulated controller: " + "; ".join(f"{r.name}, {r.what}" for r in _ROBOTS)
_LISTENERS = ", ".join(r.name for r in _ROBOTS if r.listen)
_SENDERS = ", ".join(r.name for r in _ROBOTS if r.needs_remote)
LISTEN_HELP = (f"A robot its client connects to ({_LISTENERS}): where it listens, HOST:PORT "
               "(any loopback address; default: the robot's own).")
FAULT_HELP = ("A controller's own fault, NAME=VALUE (repeatable): " + "; ".join(
    f"{r.name}: " + ", ".join(f"{n} ({w})" for n, w in r.faults) for r in _ROBOTS if r.faults)
    + ".")


def _family_faults(robot: str, given: list[str]) -> dict[str, float]:
    """``--fault NAME=VALUE`` options, checked against the robot's own faults."""
    known = dict(robots.robot(robot).faults)
    out: dict[str, float] = {}
    for item in given:
        name, sep, value = item.partition("=")
        if not sep or name not in known:
            have = ", ".join(known) or "none"
            raise ConfigError("--fault", item, f"NAME=VALUE, NAME one of the {robot} "
                              f"emulator's faults: {have}")
        try:
            out[name] = float(value)
        except ValueError:
            raise ConfigError("--fault", item, "the value must be a number") from None
    return out


def _pct(option: str, value: float) -> float:
    if not 0.0 <= value <= 100.0:
        raise ConfigError(option, str(value), "a percentage must be within 0..100")
    return value / 100.0


def _ms(option: str, value: float) -> float:
    if not (value >= 0.0 and value < 60_000.0):
        raise ConfigError(option, str(value), "must be >= 0 ms (and below a minute)")
    return value / 1000.0


@cli_errors
def emulate(
    remote: str | None = typer.Option(
        None, "--remote", help="The remote driver as IP:PORT (FRIHOST and FRISOCK on a KRC): "
        f"required by a robot that sends to its client ({_SENDERS})."
    ),
    robot: str = typer.Option(robots.default_robot(), "--robot", help=ROBOT_HELP),
    listen: str | None = typer.Option(None, "--listen", help=LISTEN_HELP),
    scene: Path | None = typer.Option(
        None, "--scene", help="Scene TOML (default: the paper's rig, data/scenes/paper.toml, "
        "with the robot's arm)."
    ),
    port: int = typer.Option(0, "--port", help="Local UDP port the KRC sends from (0 = any)."),
    cycle_ms: int = typer.Option(5, "--cycle-ms", help="FRI cycle, 1..100 ms (friOpen)."),
    pacing: str = typer.Option(
        "realtime", "--pacing", help="realtime (wall clock) or lockstep (step on each answer)."
    ),
    loss: float = typer.Option(0.0, "--loss", help="Lost datagrams, either direction (%)."),
    delay_ms: float = typer.Option(0.0, "--delay-ms", help="Added delay of each packet (ms)."),
    jitter_ms: float = typer.Option(0.0, "--jitter-ms", help="Delay jitter, |N(0, s)| (ms)."),
    duplicate: float = typer.Option(0.0, "--duplicate", help="Packets sent twice (%)."),
    reorder: float = typer.Option(0.0, "--reorder", help="Packets overtaken by the next (%)."),
    corrupt: float = typer.Option(0.0, "--corrupt", help="Packets with damaged bytes (%)."),
    netft_port: int = typer.Option(
        49152, "--netft-port", help="UDP port of the emulated Net F/T box (0 = any, -1 = none)."
    ),
    seed: int | None = typer.Option(
        None, "--seed", help="World seed (use the protocol's seed to reproduce a run)."
    ),
    set_: list[str] = typer.Option([], "--set", help="Override a scene field, e.g. --set "
                                   "target.mu=0.006 (repeatable; the same as --scene-set)."),
    scene_set: list[str] = typer.Option([], "--scene-set", help="Override a scene key, e.g. "
                                        "--scene-set target.mu=0.006 (repeatable)."),
    timeout_ms: float = typer.Option(
        1000.0, "--timeout-ms", help="Lockstep: wait this long for a command before a miss."
    ),
    duration: float = typer.Option(
        0.0, "--duration", help="Stop after this much simulated time (s), or as much wall "
        "time for a robot no client drives (0: until Ctrl-C)."
    ),
    rt: bool = typer.Option(
        False, "--rt", help="Real-time: SCHED_FIFO where the OS allows it (said when not), "
        "the garbage collector frozen and disabled while serving."
    ),
    cpu: list[int] = typer.Option([], "--cpu", help="With --rt: pin to this CPU (repeatable)."),
    camera_port: int = typer.Option(
        -1, "--camera-port", help="Serve a camera above the bed as MJPEG over HTTP on this TCP "
        "port (http://HOST:PORT/stream.mjpg; 0 = any, -1 = none)."),
    camera_fps: float = typer.Option(50.0, "--camera-fps", help="The camera's frame rate."),
    camera_calibration: Path | None = typer.Option(
        None, "--camera-calibration", help="Write the camera's calibration file here (also "
        "served at /calibration.toml) for the rig's tracker.calibration."),
    fault: list[str] = typer.Option([], "--fault", help=FAULT_HELP),
) -> None:
    """Emulate a robot controller (a KRC over FRI 1.x by default) and the Net F/T box on the
    simulated rig.

    Serves until --duration or Ctrl-C/SIGTERM, which is how an emulator is meant to end:
    the counters are printed and the exit code is 0 (a second signal: 130 at once);
    2 on bad input.
    """
    # imported here: the other commands need not load the emulator
    from drivers.config import apply_overrides, validate
    from drivers.description.scene import Scene, load_scene
    from drivers.emulate.faults import FaultSettings
    from drivers.emulate.session import EmulatedRig, EmulatedRigSettings
    from drivers.net.udp import parse_host_port

    positive("--duration", duration, allow_zero=True)
    positive("--camera-fps", camera_fps)
    check_cpus("--cpu", cpu)
    if not -1 <= camera_port <= 65535:
        raise ConfigError("--camera-port", str(camera_port), "a TCP port is -1..65535")
    positive("--timeout-ms", timeout_ms)
    for option, value in (("--port", port), ("--netft-port", netft_port)):
        low = -1 if option == "--netft-port" else 0
        if not low <= value <= 65535:
            raise ConfigError(option, str(value), f"a UDP port is {low}..65535")
    if pacing not in ("realtime", "lockstep"):
        raise ConfigError("--pacing", pacing, "choose realtime or lockstep")
    if not 1 <= cycle_ms <= 100:
        raise ConfigError("--cycle-ms", str(cycle_ms), "the FRI cycle is 1..100 ms")
    if robot not in robots.robot_names():
        raise ConfigError("--robot", robot, f"choose one of {', '.join(robots.robot_names())}")
    entry = robots.robot(robot)
    family_faults = _family_faults(robot, fault)
    if remote is None and entry.needs_remote:
        raise ConfigError("--remote", "", "the remote driver's IP:PORT is required")
    if remote is not None and not entry.needs_remote:
        raise ConfigError("--remote", remote, f"the {robot} emulator sends to no remote "
                          "driver: its client connects to it (--listen)")
    if listen is not None and entry.listen is None:
        raise ConfigError("--listen", listen, f"the {robot} emulator listens nowhere: it "
                          "sends to its remote driver (--remote)")
    remote_addr = None if remote is None else parse_host_port("--remote", remote)
    check_scene_file("--scene", scene)
    faults = FaultSettings(
        loss=_pct("--loss", loss),
        delay_s=_ms("--delay-ms", delay_ms),
        jitter_s=_ms("--jitter-ms", jitter_ms),
        duplicate=_pct("--duplicate", duplicate),
        reorder=_pct("--reorder", reorder),
        corrupt=_pct("--corrupt", corrupt),
        seed=0 if seed is None else seed,
    )
    # the default scene is the paper's rig with the robot's arm; FRI's cycle is friOpen's
    overrides = [*(entry.scene_overrides() if scene is None else ()), *set_, *scene_set]
    if entry.takes_cycle:
        overrides.append(f"fri.cycle={cycle_ms / 1000.0}")
    if scene is None:
        # an error here is an override's (the robot's own and --cycle-ms's are valid)
        sc = validate(Scene, apply_overrides({}, overrides),
                      "the paper scene with --set/--scene-set")
    else:
        sc = load_scene(scene, overrides)
        if entry.overrides_from is not None and sc.arm.model != robot:
            # a scene of another arm (the zero-g scene's LWR4+): this robot's arm in its
            # place, as the in-process simulated robot does
            sc = load_scene(scene, [*entry.scene_overrides(), *overrides])
    settings = EmulatedRigSettings(
        scene=sc,
        remote=remote_addr,
        seed=seed,
        port=port,
        pacing="lockstep" if pacing == "lockstep" else "realtime",
        lockstep_timeout_s=_ms("--timeout-ms", timeout_ms),
        faults=faults,
        netft_port=netft_port if netft_port >= 0 else None,
        camera_port=camera_port if camera_port >= 0 else None,
        camera_fps=camera_fps,
        camera_calibration=camera_calibration,
        duration_s=duration,
        robot=robot,
        listen=None if listen is None else parse_host_port("--listen", listen),
        family_faults=family_faults,
    )
    from ffexp.rt import realtime

    def say(line: str) -> None:
        print(line, file=sys.stderr, flush=True)

    flag = StopFlag()
    with EmulatedRig(settings) as rig:
        # the serving thread is started inside: it inherits the scheduling policy; this
        # (main) thread gets the signals and stops it, also while it waits for the
        # remote's first answer
        with stop_signals(flag), (realtime(tuple(cpu)) if rt else nullcontext()) as got:
            if got is not None:
                say(f"ffexp emulate: --rt: {got}")
            # the ready line comes once the handlers are in place: a signal sent on
            # reading it stops the emulator cleanly
            say(f"ffexp emulate: {rig.ready_line()}")
            waits = "a run to answer on the remote" if entry.needs_remote else "a run to connect"
            say("ffexp emulate: waiting for " + waits
                + (f"; stops after {duration:g} s" if duration > 0 else
                   "; serves until Ctrl-C (--duration S: at most S seconds)"))
            rig.serve(flag, on_status=say)
    say(f"ffexp emulate: {rig.summary()}")
