"""A run's recording read by the plain ``mcap`` reader with no ffexp code.

This module deliberately imports nothing from ffexp: the recording is made by
the ``ffexp`` command in a child process, and read back with ``mcap`` and
``mcap_ros2`` (the ROS 2 CDR decoder Foxglove's tools use) alone.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def recording(tmp_path_factory: pytest.TempPathFactory) -> Path:
    out = tmp_path_factory.mktemp("runs")
    done = subprocess.run(
        [
            sys.executable, "-c", "from ffexp.cli import main; main()", "run",
            str(ROOT / "protocols/method1_case1.toml"), "--set", "run.timeout_s=1.0",
            "--out", str(out),
        ],
        capture_output=True, text=True, timeout=600, check=False,
    )
    assert done.returncode == 4, done.stderr  # 1 s is too short to align: a timeout
    files = list(out.glob("*.mcap"))
    assert len(files) == 1
    assert str(files[0]) in done.stdout
    return files[0]


def test_plain_mcap_reader_decodes_every_message(recording: Path) -> None:
    cdr = DecoderFactory()
    counts: dict[str, int] = {}
    with recording.open("rb") as fh:
        reader = make_reader(fh)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        topics = {c.topic: c for c in summary.channels.values()}
        for topic in ("/robot/measurement", "/ft/raw", "/estimator/state", "/control/terms",
                      "/robot/command", "/robot/link", "/sim/truth", "/sim/body/target",
                      "/events", "/tf", "/runner/phase"):
            assert topic in topics
        for schema, channel, message in reader.iter_messages():
            assert schema is not None
            if channel.message_encoding == "cdr":
                assert schema.encoding == "ros2msg"
                decoded = cdr.decoder_for("cdr", schema)(message.data)
                if channel.topic == "/robot/measurement":
                    pose = np.array(decoded.msr_cart_pos).reshape(4, 4)
                    np.testing.assert_allclose(pose[3], [0, 0, 0, 1])
                    r = pose[:3, :3]
                    np.testing.assert_allclose(r @ r.T, np.eye(3), atol=1e-9)
                    assert len(decoded.jacobian) == 42
            else:
                assert channel.message_encoding == "json" and schema.encoding == "jsonschema"
                decoded = json.loads(message.data)
                if schema.name == "foxglove.FrameTransform":
                    q = decoded["rotation"]
                    assert abs(np.linalg.norm([q["x"], q["y"], q["z"], q["w"]]) - 1) < 1e-9
                if schema.name == "foxglove.Log":
                    assert 1 <= decoded["level"] <= 5 and decoded["message"]
            counts[channel.topic] = counts.get(channel.topic, 0) + 1
        by_id = summary.statistics.channel_message_counts
        for cid, channel in summary.channels.items():
            assert counts.get(channel.topic, 0) == by_id.get(cid, 0)
        # one measurement per 5 ms cycle and about five F/T samples per cycle (1 kHz)
        n_cycles = counts["/robot/measurement"]
        assert n_cycles >= 200
        assert abs(counts["/ft/raw"] - 5 * n_cycles) <= 10
        metadata = {m.name: m.metadata for m in reader.iter_metadata()}
        assert metadata["run"]["protocol"] == "method1_case1"
        attachments = {a.name for a in reader.iter_attachments()}
        assert {"method1_case1.toml", "paper.toml"} <= attachments
