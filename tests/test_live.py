"""``ffexp run --live``: a real WebSocket client (the ``websockets`` package speaking
Foxglove's WebSocket protocol) watches a simulated run, and the decimation and
dropping of the live server's tap; the run's file stays intact."""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import socket
import struct
import subprocess
import sys
import threading
from collections import defaultdict
from itertools import pairwise
from pathlib import Path
from typing import Any

import jsonschema
import pytest
import websockets
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.contracts import Phase, Progress
from ffexp.experiment import RigChoice, run_file
from ffexp.live import LiveOptions, LiveServer, parse_address
from ffexp.recording import load

ROOT = Path(__file__).resolve().parents[1]
DEADLINE_S = float(os.environ.get("LIVE_DEADLINE_S", "60"))
#: A viewer that has waited this long for a message lets the held run take one more step.
NUDGE_S = 2.0
SUBPROTOCOLS = ["foxglove.websocket.v1", "foxglove.sdk.v1"]
WANTED = ("/estimator/state", "/ft/raw", "/tf")
#: Frames a viewer's ``/tf`` must give: the tool's and the arm's last link's.
TF_FRAMES = frozenset({"tool", "link7"})


# -- the tap: decimation and dropping, without a server ---------------------------------
def _queued(server: LiveServer) -> list[tuple[str, int, bytes]]:
    return list(server._queue)


def test_high_rate_topics_are_decimated_per_topic_and_cycle() -> None:
    server = LiveServer(LiveOptions(rate_hz=50.0))  # 20 ms
    for k in range(100):  # 1 kHz samples: one in twenty goes out
        server.tap("/ft/raw", 1_000_000 * k, b"s")
    for k in range(20):  # 200 Hz cycles: /tf's frames of a cycle share its time, all go out
        t = 5_000_000 * k
        for frame in (b"tool", b"link1", b"link2"):
            server.tap("/tf", t, frame)
        server.tap("/events", t, b"e")  # low-rate JSON: every one
    items = _queued(server)
    ft = [t for topic, t, _ in items if topic == "/ft/raw"]
    assert ft == [0, 20_000_000, 40_000_000, 60_000_000, 80_000_000]
    tf = [(t, d) for topic, t, d in items if topic == "/tf"]
    assert [t for t, _ in tf] == [t for t in (0, 20_000_000, 40_000_000, 60_000_000, 80_000_000)
                                  for _ in range(3)]
    assert sum(topic == "/events" for topic, _, _ in items) == 20
    assert server.queued == len(items) and server.dropped == 0


def test_a_full_queue_drops_instead_of_waiting() -> None:
    server = LiveServer(LiveOptions(), queue_size=3)
    for k in range(10):
        server.tap("/events", k, b"e")  # never blocks: nobody takes them out
    assert server.queued == 3 and server.dropped == 7
    assert [t for _, t, _ in _queued(server)] == [0, 1, 2]


@pytest.mark.parametrize(("text", "host", "port"), [
    ("127.0.0.1:9000", "127.0.0.1", 9000), (":0", "127.0.0.1", 0), ("0.0.0.0", "0.0.0.0", 8765),
    ("[::1]:8766", "::1", 8766), ("localhost:1", "localhost", 1),
])
def test_live_addresses(text: str, host: str, port: int) -> None:
    opts = parse_address(text)
    assert (opts.host, opts.port) == (host, port)


@pytest.mark.parametrize("text", ["host:port", "h:70000", "::1:5", "[::1]x"])
def test_bad_live_address_is_one_line_exit_2(text: str, tmp_path: Path) -> None:
    result = CliRunner().invoke(app, ["run", str(ROOT / "protocols/method1_case1.toml"),
                                      "--live-address", text, "--out", str(tmp_path)])
    assert result.exit_code == 2
    lines = [x for x in result.output.splitlines() if x.strip()]
    assert lines[-1].startswith("error: --live-address: ") and text in lines[-1]
    assert len(lines) == 1 and not list(tmp_path.iterdir())


def test_a_busy_port_is_bad_input_before_anything_runs(tmp_path: Path) -> None:
    with socket.socket() as busy:
        busy.bind(("127.0.0.1", 0))
        busy.listen()
        port = busy.getsockname()[1]
        result = CliRunner().invoke(app, ["run", str(ROOT / "protocols/method1_case1.toml"),
                                          "--live-address", f"127.0.0.1:{port}",
                                          "--out", str(tmp_path)])
    assert result.exit_code == 2
    assert f"error: --live-address: 127.0.0.1:{port}: " in result.output
    assert "in use" in result.output and not list(tmp_path.iterdir())


def test_help_does_not_import_foxglove() -> None:
    code = ("import sys\nsys.argv = ['ffexp', 'run', '--help']\nfrom ffexp.cli import main\n"
            "try:\n    main()\nexcept SystemExit:\n    pass\n"
            "print('FOXGLOVE', 'foxglove' in sys.modules, 'websockets' in sys.modules)")
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True,
                          cwd=ROOT, timeout=120, env={**os.environ, "COLUMNS": "200"})
    assert "--live-address" in done.stdout
    assert "FOXGLOVE False False" in done.stdout


# -- a viewer during a simulated run ----------------------------------------------------
class Gate:
    """Holds the run (in its progress callback, every 0.1 s of run time) until a viewer
    grants it more progress steps; ``open`` lets it run to its end. Deadlines, no sleeps."""

    def __init__(self) -> None:
        self.credits = threading.Semaphore(0)
        self.opened = threading.Event()
        self.url = ""
        self.url_ready = threading.Event()
        self.timed_out = False

    def progress(self, _p: Progress) -> None:
        if not self.opened.is_set() and not self.credits.acquire(timeout=DEADLINE_S):
            self.timed_out = True
            self.opened.set()

    def notice(self, line: str) -> None:
        m = re.search(r"ws://\S+", line)
        if m:
            self.url = m.group(0)
            self.url_ready.set()

    def grant(self, steps: int) -> None:
        self.credits.release(steps)

    def open(self) -> None:
        self.opened.set()
        self.credits.release(1000)


async def _viewer(gate: Gate, steps: int) -> dict[str, Any]:
    """Connect, subscribe to the wanted topics as they are advertised, let the run
    go on for ``steps`` progress steps, collect messages until each wanted topic
    has some and ``/tf`` has given the tool's and the last link's frames (the frames of
    one cycle arrive one by one: five of them may be part of one instant), disconnect."""
    channels: dict[int, dict[str, Any]] = {}
    subs: dict[int, int] = {}
    got: dict[str, list[tuple[int, bytes]]] = defaultdict(list)
    granted = False
    starved_s = 0.0
    children: set[str] = set()
    async with websockets.connect(gate.url, subprotocols=SUBPROTOCOLS, close_timeout=0.5) as ws:
        info = json.loads(await asyncio.wait_for(ws.recv(), DEADLINE_S))
        assert info["op"] == "serverInfo"
        while not (all(len(got[t]) >= 5 for t in WANTED) and TF_FRAMES <= children):
            try:
                frame = await asyncio.wait_for(ws.recv(), NUDGE_S)
            except TimeoutError:
                # the run used its steps before a subscription took effect (a loaded
                # machine): one more step at a time, until the deadline
                starved_s += NUDGE_S
                assert granted and starved_s < DEADLINE_S, f"no messages: {dict(got)}"
                gate.grant(1)
                continue
            if isinstance(frame, str):
                msg = json.loads(frame)
                if msg["op"] != "advertise":
                    continue
                new = []
                for ch in msg["channels"]:
                    channels[ch["id"]] = ch
                    if ch["topic"] in WANTED:
                        subs[len(subs) + 1] = ch["id"]
                        new.append({"id": len(subs), "channelId": ch["id"]})
                if new:
                    await ws.send(json.dumps({"op": "subscribe", "subscriptions": new}))
                subscribed = {channels[c]["topic"] for c in subs.values()}
                if not granted and {"/estimator/state", "/tf"} <= subscribed:  # /ft/raw: later
                    gate.grant(steps)
                    granted = True
                continue
            assert frame[0] == 0x01  # message data
            sub_id, log_time = struct.unpack_from("<IQ", frame, 1)
            topic = channels[subs[sub_id]]["topic"]
            got[topic].append((log_time, bytes(frame[13:])))
            if topic == "/tf":
                children.add(json.loads(bytes(frame[13:]))["child_frame_id"])
    return {"channels": {ch["topic"]: ch for ch in channels.values()}, "got": dict(got)}


def _file_messages(path: Path) -> dict[tuple[str, int], set[bytes]]:
    out: dict[tuple[str, int], set[bytes]] = defaultdict(set)
    with path.open("rb") as fh:
        for _s, channel, message in make_reader(fh).iter_messages(topics=list(WANTED)):
            out[(channel.topic, message.log_time)].add(message.data)
    return out


@pytest.mark.slow
def test_a_viewer_connects_during_a_run_receives_decodable_messages_and_leaves(
        tmp_path: Path) -> None:
    gate = Gate()
    result: dict[str, Any] = {}

    def run() -> None:
        try:
            result["run"] = run_file(
                ROOT / "protocols/method1_case1.toml", ["run.timeout_s=1.5"],
                rig=RigChoice(driver="sim"), out_dir=tmp_path, progress=gate.progress,
                notice=gate.notice, live=LiveOptions(port=0))
        except BaseException as exc:  # reported by the test thread
            result["error"] = exc
            gate.url_ready.set()

    thread = threading.Thread(target=run)
    thread.start()
    try:
        assert gate.url_ready.wait(DEADLINE_S) and gate.url.startswith("ws://127.0.0.1:")
        first = asyncio.run(_viewer(gate, steps=5))
        second = asyncio.run(_viewer(gate, steps=5))  # another viewer after the first left
    finally:
        gate.open()
        thread.join(DEADLINE_S)
    assert not thread.is_alive() and "error" not in result, result.get("error")
    assert not gate.timed_out
    outcome = result["run"].outcome
    assert outcome.phase in (Phase.DONE, Phase.ABORT) and outcome.stop_reason.value == "timeout"
    assert outcome.duration_s >= 1.5

    rec = load(result["run"].path)  # the file is whole: summary, every topic readable
    assert rec.complete and not rec.warnings
    in_file = _file_messages(result["run"].path)
    decoders = DecoderFactory()
    period_ns = round(1e9 / LiveOptions().rate_hz)
    for view in (first, second):
        chans = view["channels"]
        for topic in ("/estimator/state", "/ft/raw"):
            ch = chans[topic]
            assert (ch["encoding"], ch["schemaEncoding"]) == ("cdr", "ros2msg")
            decode = decoders.decoder_for("cdr", Schema(
                id=ch["id"], name=ch["schemaName"], encoding="ros2msg", data=ch["schema"].encode()))
            times = [t for t, _ in view["got"][topic]]
            assert min(b - a for a, b in pairwise(times)) >= period_ns
            for t, data in view["got"][topic]:
                assert data in in_file[(topic, t)]  # the file's own bytes at its log time
                msg = decode(data)
                assert len(msg.wrench) == 6
                if topic == "/estimator/state":
                    assert msg.f_z == -msg.wrench[2]
        ch = chans["/tf"]
        assert (ch["encoding"], ch["schemaEncoding"], ch["schemaName"]) == (
            "json", "jsonschema", "foxglove.FrameTransform")
        schema = json.loads(ch["schema"])
        children = set()
        for t, data in view["got"]["/tf"]:
            assert data in in_file[("/tf", t)]
            msg = json.loads(data)
            jsonschema.validate(msg, schema)
            assert msg["timestamp"]["sec"] * 10**9 + msg["timestamp"]["nsec"] == t
            children.add(msg["child_frame_id"])
        assert TF_FRAMES <= children



# -- the layout file ----------------------------------------------------------------------
def test_the_layout_file_is_the_generated_one_and_reads_existing_fields() -> None:
    from ffexp.live import layout
    from ffexp.recording.topics import CDR_TOPICS, JSON_TOPICS

    text = (ROOT / "layouts/ffexp-layout.json").read_text()
    assert text == layout.text(), "run: python -m ffexp.live.layout"
    data = json.loads(text)
    ids = set(data["configById"])
    assert {"3D!rig", "Plot!force", "Plot!wrench", "StateTransitions!phase"} <= ids

    def leaves(node: Any) -> list[str]:
        return [node] if isinstance(node, str) else leaves(node["first"]) + leaves(
            node["second"])

    assert sorted(leaves(data["layout"])) == sorted(ids)  # every panel placed once
    paths = layout.plotted_paths()
    assert "/estimator/state.f_z" in paths and "/control/terms.f_ref[2]" in paths
    for path in paths:
        m = re.fullmatch(r"(/[\w/]+)\.(\w+)(?:\[(\d+)\])?", path)
        assert m, path
        topic, field, index = m.groups()
        if topic in CDR_TOPICS:
            spec = {f.name: f for f in CDR_TOPICS[topic].spec.fields}
            assert field in spec, path
            assert (index is None) == (spec[field].count == 1), path
            assert index is None or int(index) < spec[field].count, path
        else:
            assert field in JSON_TOPICS[topic].schema["properties"], path
    assert set(data["configById"]["3D!rig"]["topics"]) <= set(JSON_TOPICS)


# -- after the run: a late viewer, the subprotocols, Ctrl-C -----------------------------------
class LiveRun:
    """``ffexp run --live`` in a subprocess (signals need its main thread); reads its stderr
    line by line, each wait bounded by a deadline, never by a fixed time."""

    def __init__(self, tmp_path: Path) -> None:
        self.proc = subprocess.Popen(
            [sys.executable, "-m", "ffexp", "run", str(ROOT / "protocols/method1_case1.toml"),
             "--live-address", "127.0.0.1:0", "--set", "run.timeout_s=1", "--out",
             str(tmp_path)],
            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, cwd=ROOT,
            env={**os.environ, "PYTHONPATH": str(ROOT)})
        self.lines: list[str] = []
        self.url = ""

    def wait_for(self, text: str) -> str:
        assert self.proc.stderr is not None
        for line in self.proc.stderr:  # ends when the process does
            self.lines.append(line.rstrip())
            m = re.search(r"server on (ws://\S+)", line)
            if m:
                self.url = m.group(1)
            if text in line:
                return line
        raise AssertionError(f"{text!r} never came: {self.lines}")

    def finish(self) -> tuple[int, str, str]:
        out, err = self.proc.communicate(timeout=DEADLINE_S)
        return self.proc.returncode, out, "\n".join(self.lines) + err


async def _late_viewer(url: str, subprotocols: list[str]) -> tuple[str | None, dict[str, Any],
                                                                    set[str]]:
    """Connect, take the advertisements, subscribe to /tf and the scene, read the last
    instant the server sends again, disconnect."""
    async with websockets.connect(url, subprotocols=subprotocols, close_timeout=0.5) as ws:
        assert json.loads(await asyncio.wait_for(ws.recv(), DEADLINE_S))["op"] == "serverInfo"
        adv = json.loads(await asyncio.wait_for(ws.recv(), DEADLINE_S))
        assert adv["op"] == "advertise"
        channels = {ch["topic"]: ch for ch in adv["channels"]}
        wanted = ["/tf", "/scene/rig"]
        await ws.send(json.dumps({"op": "subscribe", "subscriptions": [
            {"id": k, "channelId": channels[t]["id"]} for k, t in enumerate(wanted)]}))
        got: set[str] = set()
        while got != set(wanted):
            frame = await asyncio.wait_for(ws.recv(), DEADLINE_S)
            if isinstance(frame, bytes):
                got.add(wanted[struct.unpack_from("<I", frame, 1)[0]])
        return ws.subprotocol, channels, got


@pytest.mark.slow
@pytest.mark.parametrize("offered", [
    ["foxglove.sdk.v1"],
    ["foxglove.sdk.v1", "foxglove.websocket.v1"],  # what the Foxglove app offers
])
def test_a_viewer_connecting_after_the_run_ended_gets_its_topics_and_ends_the_server(
        tmp_path: Path, offered: list[str]) -> None:
    run = LiveRun(tmp_path)
    try:
        run.wait_for("still serving")  # the run is over: no viewer could have been this fast
        assert run.proc.poll() is None
        assert any("Open connection -> Foxglove WebSocket -> " + run.url in x for x in run.lines)
        subprotocol, channels, got = asyncio.run(_late_viewer(run.url, offered))
        code, out, err = run.finish()
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
    assert subprotocol == "foxglove.sdk.v1"
    recording = next(tmp_path.glob("*.mcap"))
    rec = load(recording)
    # every recorded topic is advertised; a frame fixed on a body is recorded once, as its
    # offset on /sim/attached, and its /sim/site/<name> only resolved on reading
    fixed = {f"/sim/site/{name}" for m in rec.json["/sim/attached"].messages
             for name in m["frames"]}
    assert fixed and "/sim/attached" in channels
    assert set(rec.topics) - fixed <= set(channels)
    assert got == {"/tf", "/scene/rig"}  # the last instant, sent again to the late viewer
    assert code == 4, err  # the run's own exit code: timed out without aligning
    assert "live: stopped serving (the viewer disconnected)" in err
    assert "timeout" in out


@pytest.mark.slow
def test_ctrl_c_ends_serving_after_the_run_with_the_runs_exit_code(tmp_path: Path) -> None:
    run = LiveRun(tmp_path)
    try:
        run.wait_for("still serving")
        run.proc.send_signal(signal.SIGINT)
        code, _out, err = run.finish()
    finally:
        if run.proc.poll() is None:
            run.proc.kill()
    assert code == 4 and "live: stopped serving (stopped)" in err and "Traceback" not in err


def test_a_client_offering_only_the_old_subprotocol_is_refused() -> None:
    """foxglove-sdk's server speaks the protocol under ``foxglove.sdk.v1`` only; a client
    offering only ``foxglove.websocket.v1`` (the ws-protocol specification's name) gets
    HTTP 400. The docs name foxglove.sdk.v1 (ffexp.live.server.SUBPROTOCOL)."""
    from ffexp.live.server import SUBPROTOCOL

    async def connect(url: str, offered: list[str]) -> str | None:
        async with websockets.connect(url, subprotocols=offered, close_timeout=0.5) as ws:
            return ws.subprotocol

    with LiveServer(LiveOptions(port=0)) as server:
        assert asyncio.run(connect(server.url, [SUBPROTOCOL])) == SUBPROTOCOL
        with pytest.raises(websockets.InvalidStatus) as refused:
            asyncio.run(connect(server.url, ["foxglove.websocket.v1"]))
    assert refused.value.response.status_code == 400
