"""``ffexp friction synth|estimate`` through typer's CliRunner and once as a process."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest
from mcap.reader import make_reader
from typer.testing import CliRunner

from ffexp.cli import app

runner = CliRunner()

REQUIRED = {
    "mu": float,
    "mu_std": float,
    "mu_upper_bound": float,
    "significant": bool,
    "decel_mps2": float,
    "v0_mps": float,
    "window_s": float,
    "frames_used": int,
}


def _synth(tmp: Path, name: str, *extra: str) -> tuple[Path, Path]:
    video, truth = tmp / f"{name}.avi", tmp / f"{name}.json"
    args = ["friction", "synth", "--out", str(video), "--truth", str(truth), "--seed", "7"]
    result = runner.invoke(app, [*args, *extra])
    assert result.exit_code == 0, result.output
    assert video.stat().st_size > 0
    return video, truth


def test_synth_then_estimate_json_plot_and_record(tmp_path: Path) -> None:
    video, truth_path = _synth(
        tmp_path, "a", "--mu", "0.02", "--v0", "0.2", "--duration", "1.0",
        "--size", "640x360", "--px-per-m", "565", "--rest-s", "0.4",
    )  # fmt: skip
    truth = json.loads(truth_path.read_text())
    assert truth["mu"] == 0.02
    assert len(truth["centre_px"]) == 50
    plot, record = tmp_path / "a.png", tmp_path / "a.mcap"
    result = runner.invoke(
        app,
        ["friction", "estimate", str(video), "--px-per-m", "565", "--json",
         "--plot", str(plot), "--record", str(record)],
    )  # fmt: skip
    assert result.exit_code == 0, result.output
    d = json.loads(result.stdout)
    for key, kind in REQUIRED.items():
        assert isinstance(d[key], kind), key
    assert abs(d["mu"] - 0.02) <= 0.002
    assert plot.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    with record.open("rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None
        topics = {c.topic: c.id for c in summary.channels.values()}
        assert set(topics) == {"/friction/track", "/friction/result"}
        counts = summary.statistics.channel_message_counts
        assert counts[topics["/friction/result"]] == 1
        assert counts[topics["/friction/track"]] == d["frames_read"]
        msgs = [json.loads(m.data) for _, _, m in reader.iter_messages(["/friction/result"])]
    assert msgs[0]["mu"] == pytest.approx(d["mu"])


def test_default_1280x720_video_and_human_output(tmp_path: Path) -> None:
    # defaults: 1280x720 at 50 fps; a short, strongly braked slide
    video, _ = _synth(
        tmp_path, "hd", "--mu", "0.05", "--v0", "0.2", "--duration", "0.9", "--px-per-m", "1130"
    )
    result = runner.invoke(app, ["friction", "estimate", str(video), "--px-per-m", "1130"])
    assert result.exit_code == 0, result.output
    first = result.stdout.splitlines()[0]
    assert first.startswith("mu = ")
    mu = float(first.split()[2])
    assert abs(mu - 0.05) <= 0.005
    # the uncertainty is shown with two significant digits, never as 0.00000
    std_text = first.split()[4]
    assert float(std_text) > 0 and len(std_text.lstrip("0.")) == 2


@pytest.mark.parametrize(
    ("value", "std", "text"),
    [
        (0.0050001, 2.9e-7, "0.00500010 ± 0.00000029"),
        (0.0123456, 0.00042, "0.01235 ± 0.00042"),
        (12.345, 1.5, "12.3 ± 1.5"),
        (123.4, 25.0, "123 ± 25"),
        (0.005, 0.0, "0.005 ± 0"),
    ],
)
def test_plus_minus_keeps_the_uncertainty_visible(value: float, std: float, text: str) -> None:
    from ffexp.numfmt import pm

    assert pm(value, std) == text


def test_zero_friction_prints_a_bound(tmp_path: Path) -> None:
    video, _ = _synth(
        tmp_path, "z", "--mu", "0", "--v0", "0.1", "--duration", "1.2",
        "--size", "640x360", "--px-per-m", "565", "--rest-s", "0.4",
    )  # fmt: skip
    result = runner.invoke(app, ["friction", "estimate", str(video), "--px-per-m", "565"])
    assert result.exit_code == 0, result.output
    assert result.stdout.startswith("mu < ")


def _one_error_line(stderr: str, name: str) -> None:
    lines = stderr.strip().splitlines()
    assert len(lines) == 1, stderr
    assert lines[0].startswith("error: ")
    assert name in lines[0]
    assert "Traceback" not in stderr


def test_unreadable_video_is_one_line(tmp_path: Path) -> None:
    bad = tmp_path / "garbage.avi"
    bad.write_bytes(b"\x00\x01 not a video" * 200)
    result = runner.invoke(app, ["friction", "estimate", str(bad), "--px-per-m", "1000"])
    assert result.exit_code != 0
    _one_error_line(result.stderr, "garbage.avi")
    assert result.stdout == ""


def test_object_leaving_immediately_is_one_line(tmp_path: Path) -> None:
    # 2 m/s from near the right edge: out of the frame within three frames
    video, _ = _synth(
        tmp_path, "gone", "--mu", "0.01", "--v0", "2", "--duration", "0.6",
        "--size", "640x360", "--px-per-m", "565", "--rest-s", "0.3", "--start-px", "540,180",
    )  # fmt: skip
    result = runner.invoke(app, ["friction", "estimate", str(video), "--px-per-m", "565"])
    assert result.exit_code != 0
    _one_error_line(result.stderr, "gone.avi")
    assert "leaves the frame" in result.stderr


def test_bad_options_are_one_line(tmp_path: Path) -> None:
    video = tmp_path / "x.avi"
    result = runner.invoke(app, ["friction", "estimate", str(video)])
    assert result.exit_code != 0
    _one_error_line(result.stderr, "scale")
    result = runner.invoke(
        app, ["friction", "synth", "--out", str(video), "--size", "big", "--duration", "0.1"]
    )
    assert result.exit_code != 0
    _one_error_line(result.stderr, "--size")
    result = runner.invoke(
        app, ["friction", "synth", "--out", str(video), "--mu", "-1", "--duration", "0.1"]
    )
    assert result.exit_code != 0
    _one_error_line(result.stderr, "mu")


def test_missing_file_as_a_process(tmp_path: Path) -> None:
    missing = tmp_path / "nowhere.mp4"
    proc = subprocess.run(
        [sys.executable, "-c", "from ffexp.cli import main; main()",
         "friction", "estimate", str(missing), "--px-per-m", "1000"],
        capture_output=True, text=True, timeout=120, check=False,
    )  # fmt: skip
    assert proc.returncode != 0
    _one_error_line(proc.stderr, "nowhere.mp4")
    assert proc.stdout == ""


@pytest.mark.parametrize("option", ["--out", "--truth"])
def test_synth_into_a_directory_is_one_line_as_a_process(tmp_path: Path, option: str) -> None:
    """A directory where the video (or its truth) goes: one line naming the option, before
    OpenCV's writer prints its own warnings straight to the process's stderr."""
    args = {"--out": str(tmp_path / "v.avi"), "--truth": str(tmp_path / "t.json")}
    args[option] = str(tmp_path)
    done = subprocess.run([sys.executable, "-m", "ffexp", "friction", "synth",
                           *[x for kv in args.items() for x in kv], "--duration", "0.2"],
                          capture_output=True, text=True, timeout=120)
    lines = [x for x in done.stderr.splitlines() if x.strip()]
    assert done.returncode == 2 and len(lines) == 1, done.stderr
    assert lines[0] == f"error: {option}: {tmp_path}: is a directory, expected a file name"
    assert not (tmp_path / "v.avi").exists() and not (tmp_path / "t.json").exists()
