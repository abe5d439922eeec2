"""The emulated FR3's controller and server in-process: the ``RobotState`` it writes in place
equals the same state encoded field by field from the world's state; the success rate is the
share of the last 100 cycles answered; the world's F/T samples, which the FR3 has no reader
for, are not kept; and ``ffexp emulate``'s serving thread is started where it takes the
caller's CPU affinity (what ``--rt`` set)."""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np
import pytest

from drivers.description.scene import load_scene
from drivers.franka import codec
from drivers.franka.emulate.controller import WINDOW, Fr3SimController, flange_to_tcp
from drivers.franka.emulate.served import ServedFr3
from drivers.franka.emulate.server import FciServer
from drivers.world.world import SimWorld

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def scene():  # type: ignore[no-untyped-def]
    return load_scene(ROOT / "data/scenes/paper-fr3.toml", [])


def plain_state(c: Fr3SimController) -> bytes:
    """The state ``c`` reports, encoded field by field from the world's state (float64
    values cast to float32 by numpy, poses column-major)."""
    w = c.world
    st = w.last_state
    s = np.zeros((), dtype=codec.ROBOT_STATE)
    s["message_id"] = c.message_id
    s["O_T_EE"] = s["O_T_EE_d"] = st.tcp_pose_m.ravel(order="F")
    s["F_T_EE"] = s["F_T_NE"] = flange_to_tcp(w).ravel(order="F")
    s["EE_T_K"] = s["NE_T_EE"] = np.eye(4).ravel(order="F")
    s["O_ddP_O"] = (0.0, 0.0, -9.81)
    s["elbow"] = (0.0, -1.0)
    s["q"] = s["theta"] = st.jnt_pos_rad
    s["dq"] = s["dtheta"] = w.arm_qvel
    s["q_d"] = c._q_d if c.moving else st.jnt_pos_rad
    s["dq_d"] = c._dq_d if c.moving else 0.0
    s["tau_J_d"] = c._tau
    s["tau_J"] = st.jnt_trq_nm
    s["tau_ext_hat_filtered"] = st.ext_jnt_trq_nm
    f = st.ext_wrench_n_nm
    rot = st.tcp_pose_m[:3, :3]
    s["K_F_ext_hat_K"] = f
    s["O_F_ext_hat_K"] = np.concatenate((rot @ f[:3], rot @ f[3:]))
    if c.moving:
        s["motion_generator_mode"] = c._generator
        s["controller_mode"] = c._controller
        s["robot_mode"] = codec.RobotMode.MOVE
    else:
        s["controller_mode"] = codec.ControllerMode.JOINT_IMPEDANCE
        s["robot_mode"] = codec.RobotMode.REFLEX if c.reflex else codec.RobotMode.IDLE
    for name in c.reflex:
        s["errors"][codec.ERROR_NAMES.index(name)] = 1
        s["reflex_reason"][codec.ERROR_NAMES.index(name)] = 1
    s["control_command_success_rate"] = c.success_rate
    return s.tobytes()


def command(c: Fr3SimController, tau: np.ndarray, answer: bool = True) -> np.void:
    cmd = np.zeros((), dtype=codec.ROBOT_COMMAND)
    cmd["message_id"] = c.message_id if answer else c.message_id - 1
    cmd["tau_J_d"] = tau
    return codec.decode(codec.ROBOT_COMMAND, cmd.tobytes())


def test_the_state_written_in_place_equals_the_state_encoded_field_by_field(scene) -> None:  # type: ignore[no-untyped-def]
    c = Fr3SimController(SimWorld(scene, seed=0))
    rng = np.random.default_rng(7)
    modes = set()
    for n in range(400):
        if n == 20:
            c.start_motion()
        if n == 250:
            c.inject_reflex()
        if n == 300:
            c.recover()
        if n == 320:
            c.start_motion()
        tau = np.zeros(7) if n < 100 else rng.normal(0.0, 0.5, 7)
        c.step(command(c, tau, answer=n % 13 != 0) if n % 29 else None)
        got = c.state().tobytes()
        assert got == plain_state(c), f"cycle {n}"
        rec = codec.decode(codec.ROBOT_STATE, got)
        modes.add((int(rec["robot_mode"]), tuple(codec.error_names(rec["errors"]))))
    # the run went through idle, moving, a reflex and its recovery
    assert modes >= {(int(codec.RobotMode.IDLE), ()), (int(codec.RobotMode.MOVE), ()),
                     (int(codec.RobotMode.REFLEX), ("cartesian_reflex",))}


def test_the_success_rate_is_the_share_of_the_last_window_answered(scene) -> None:  # type: ignore[no-untyped-def]
    c = Fr3SimController(SimWorld(scene, seed=0))
    c.start_motion()
    zero = np.zeros(7)
    for _ in range(7):  # commands that came for an older state: not answered
        c.step(command(c, zero, answer=False))
    for _ in range(3):
        c.step(None)
    assert c.success_rate == (WINDOW - 10) / WINDOW
    for _ in range(WINDOW - 10):
        c.step(command(c, zero))
    assert c.success_rate == (WINDOW - 10) / WINDOW  # the misses still in the window
    for _ in range(10):
        c.step(command(c, zero))
    assert c.success_rate == 1.0


def test_the_worlds_ft_samples_are_not_kept(scene) -> None:  # type: ignore[no-untyped-def]
    w = SimWorld(scene, seed=0)
    c = Fr3SimController(w)
    for _ in range(50):
        c.step(None)
    assert len(w.ft_samples().seq) == 0
    # the world does produce them: a step of the world alone leaves its samples
    w.advance(None)
    assert len(w.ft_samples().seq) > 0


@pytest.mark.skipif(not hasattr(os, "sched_setaffinity"), reason="no CPU affinity here")
def test_the_serving_thread_is_started_by_serve_and_takes_the_callers_cpus(scene) -> None:  # type: ignore[no-untyped-def]
    server = FciServer(SimWorld(scene, seed=0), "127.0.0.1", 0)
    served = ServedFr3(server)
    assert not server.started  # listening, not serving, until serve()
    old = os.sched_getaffinity(0)
    cpu = min(old)
    seen: list[set[int]] = []

    def stop_requested() -> bool:
        thread = server._thread
        assert thread is not None and thread.native_id is not None
        seen.append(os.sched_getaffinity(thread.native_id))
        return True

    try:
        os.sched_setaffinity(0, {cpu})  # as ffexp emulate --rt --cpu does, before serving
        served.serve(stop_requested, None, lambda: None, None, 0.0)
    finally:
        os.sched_setaffinity(0, old)
        served.close()
    assert seen == [{cpu}]


@pytest.mark.parametrize("controller", [codec.MoveControllerMode.EXTERNAL_CONTROLLER,
                                        codec.MoveControllerMode.JOINT_IMPEDANCE])
def test_a_command_read_in_place_is_copied_when_kept(scene, controller) -> None:  # type: ignore[no-untyped-def]
    """The server hands the controller a view of its receive buffer: the next datagram
    written there must not change the torque or joint set-point already taken."""
    c = Fr3SimController(SimWorld(scene, seed=0))
    c.start_motion(codec.MoveMotionGeneratorMode.JOINT_POSITION, controller)
    buf = bytearray(codec.ROBOT_COMMAND.itemsize)
    rec = np.frombuffer(buf, dtype=codec.ROBOT_COMMAND, count=1)[0]
    q0 = c.world.arm_qpos.copy()
    rec["message_id"] = c.message_id
    rec["tau_J_d"] = np.full(7, 0.1)
    rec["q_c"] = q0 + 1e-4
    c.step(rec)
    kept = c.state().copy()
    rec["tau_J_d"] = np.full(7, 0.3)  # the next datagram, for an older state: not taken
    rec["q_c"] = q0 - 1e-2
    assert kept["tau_J_d"].tolist() == c.state()["tau_J_d"].tolist()
    assert kept["q_d"].tolist() == c.state()["q_d"].tolist()


def test_in_real_time_a_command_while_no_motion_runs_is_counted_late(scene) -> None:  # type: ignore[no-untyped-def]
    """No motion: the server waits for no command (the world holds every millisecond) and
    a command that comes anyway answers no state: counted late, the arm still held."""
    import socket

    server = FciServer(SimWorld(scene, seed=0), "127.0.0.46", 0).start()
    udp = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    try:
        udp.bind(("127.0.0.46", 0))
        udp.settimeout(5.0)
        tcp = socket.create_connection(server.address, timeout=5.0,
                                       source_address=("127.0.0.46", 0))
        tcp.sendall(codec.message(codec.CONNECT_REQUEST, codec.Command.CONNECT, 1,
                                  version=codec.VERSION, udp_port=udp.getsockname()[1]))
        answer = codec.decode(codec.CONNECT_RESPONSE, tcp.recv(codec.CONNECT_RESPONSE.itemsize))
        assert int(answer["status"]) == codec.ConnectStatus.SUCCESS
        data, robot = udp.recvfrom(4096)
        first = codec.decode(codec.ROBOT_STATE, data)
        cmd = np.zeros((), dtype=codec.ROBOT_COMMAND)
        cmd["message_id"] = int(first["message_id"]) + 1
        cmd["tau_J_d"] = np.full(7, 1.0)
        udp.sendto(cmd.tobytes(), robot)
        for _ in range(50):  # 50 more states: 50 ms served
            last = codec.decode(codec.ROBOT_STATE, udp.recv(4096))
        tcp.close()
    finally:
        udp.close()
        server.close()
    assert server.counters["late"] == 1 and "answered" not in server.counters
    assert int(last["message_id"]) >= int(first["message_id"]) + 50
    assert int(last["robot_mode"]) == codec.RobotMode.IDLE
    assert last["tau_J_d"].tolist() == [0.0] * 7  # the torques were not taken
