"""ffexp replay, diff and export: bad input is one line naming the culprit, exit 2; and
diff's alignment of recordings with different time bases, against closed forms.

The recordings are written here with the Recorder (no simulation): a small "run"
with the recorded protocol in its metadata, one without it, one without
``/robot/state``. ``CASES`` is the battery (``tests/test_bad_input.py`` style).
"""

from __future__ import annotations

import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from test_bad_input import check_one_line, expand  # the battery's own checks
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.diff import diff
from ffexp.protocol import load_run_protocol
from ffexp.recording import Recorder, load

ROOT = Path(__file__).resolve().parents[1]
PROTOCOL = ROOT / "protocols/method1_case1.toml"
START_NS = 1_750_000_000 * 10**9
runner = CliRunner()


def write_run(path: Path, *, period_ms: int, span_s: float, start_ns: int = START_NS,
              f_z: object = math.sin, protocol: bool = True, state: bool = True) -> Path:
    """A recording with ``/robot/state`` and ``/estimator/state`` every ``period_ms``
    (``f_z`` a function of run time), optionally the recorded protocol."""
    with Recorder(path) as rec:
        if protocol:
            p = load_run_protocol(PROTOCOL)
            rec.metadata("run", {"protocol": p.name, "protocol_json": p.model_dump_json()})
        n = round(span_s * 1000 / period_ms) + 1
        for i in range(n):
            t_ns = i * period_ms * 1_000_000
            if state:
                r = rec.record("/robot/state")
                r["time_ns"] = 10**12 + t_ns
                r["tcp_pose"] = np.eye(4).reshape(-1)
                r["n_joints"] = 7
                r["commanding"] = 1
                r["healthy"] = 1
                r["cycle"] = i
                r["cycle_s"] = period_ms / 1000
                rec.write("/robot/state", start_ns + t_ns)
            e = rec.record("/estimator/state")
            e["f_z"] = f_z(t_ns / 1e9)  # type: ignore[operator]
            e["wrench"] = [0.0, 0.0, -e["f_z"][0], 0.0, 0.0, 0.0]
            rec.write("/estimator/state", start_ns + t_ns)
        rec.log(start_ns, "INFO", "phase", "start")
        rec.write_json("/runner/phase", start_ns + t_ns, {  # the run's end: a whole run
            "phase": "DONE", "phase_id": 3, "reason": "test", "stop_reason": "timeout",
            "aligned": False})
    return path


@pytest.fixture(scope="module")
def files(tmp_path_factory: pytest.TempPathFactory) -> dict[str, str]:
    d = tmp_path_factory.mktemp("data_bad")
    (d / "text.mcap").write_text("not an mcap file\n")
    (d / "a_dir").mkdir()
    (d / "a_file.txt").write_text("x")
    return {
        "tmp": str(d),
        "rec": str(write_run(d / "rec.mcap", period_ms=5, span_s=0.1)),
        "noproto": str(write_run(d / "noproto.mcap", period_ms=5, span_s=0.1, protocol=False)),
        "nostate": str(write_run(d / "nostate.mcap", period_ms=5, span_s=0.1, state=False)),
        "text": str(d / "text.mcap"),
        "dir": str(d / "a_dir"),
        "file": str(d / "a_file.txt"),
    }


CASES: list[tuple[str, list[str]]] = [
    ("replay {tmp}/nope.mcap --out {tmp}/o.mcap", ["nope.mcap", "not found"]),
    ("replay {text} --out {tmp}/o.mcap", ["text.mcap", "not an MCAP"]),
    ("replay {dir} --out {tmp}/o.mcap", ["a_dir", "directory"]),
    ("replay {rec} --out {tmp}/o.csv", ["o.csv", "--out"]),
    ("replay {rec} --out {rec}", ["rec.mcap", "--out must differ"]),
    ("replay {rec} --out {dir}", ["a_dir", "--out"]),
    ("replay {rec}", ["--out"]),
    ("replay {nostate} --out {tmp}/o.mcap", ["nostate.mcap", "/robot/state"]),
    ("replay {noproto} --out {tmp}/o.mcap", ["noproto.mcap", "protocol_json", "--protocol"]),
    ("replay {rec} --out {tmp}/o.mcap --set align.k_ri=[1,2]", ["rec.mcap", "align.k_ri"]),
    ("replay {rec} --out {tmp}/o.mcap --set align.kp=[0,0,1,0,0,0.5]", ["align", "kp", "rz"]),
    ("replay {rec} --out {tmp}/o.mcap --set nonsense", ["--set", "nonsense"]),
    ("replay {rec} --out {tmp}/o.mcap --set run.nope=1", ["run.nope", "unknown key"]),
    ("replay {rec} --out {tmp}/o.mcap --protocol {tmp}/nope.toml", ["nope.toml"]),
    ("replay {rec} --out {tmp}/o.mcap --protocol {file}", ["a_file.txt"]),
    ("diff {rec} {tmp}/nope.mcap", ["nope.mcap", "not found"]),
    ("diff {text} {rec}", ["text.mcap"]),
    ("diff {rec} {rec} --rtol -1", ["--rtol", "-1"]),
    ("diff {rec} {rec} --atol nan", ["--atol", "nan"]),
    ("diff {rec} {rec} --topic /nope", ["/nope", "either recording"]),
    ("diff {rec} {rec} --topic /events", ["/events", "JSON"]),
    ("diff {rec} {rec} --plots {file}", ["a_file.txt"]),
    ("diff {rec}", ["argument 'b'"]),
    ("export {rec} --format xlsx", ["--format", "xlsx"]),
    ("export {rec} --topic /nope --out {tmp}/t", ["rec.mcap", "/nope"]),
    ("export {rec} --out {file}", ["a_file.txt", "not a directory"]),
    ("export {tmp}/nope.mcap", ["nope.mcap", "not found"]),
    ("export {text}", ["text.mcap", "not an MCAP"]),
]


@pytest.mark.parametrize(("line", "needles"), CASES, ids=[c[0] for c in CASES])
def test_bad_input_is_one_line_exit_2(files: dict[str, str], line: str,
                                      needles: list[str]) -> None:
    result = runner.invoke(app, expand(line, files))
    check_one_line(result.exit_code, result.stdout, result.stderr,
                   [n.format(**files) for n in needles])


def test_bad_input_of_replay_in_a_subprocess(files: dict[str, str]) -> None:
    done = subprocess.run(
        [sys.executable, "-m", "ffexp", *expand(CASES[9][0], files)],
        capture_output=True, text=True, timeout=120, cwd=files["tmp"])
    check_one_line(done.returncode, done.stdout, done.stderr, ["align.k_ri"])


def test_no_bad_input_leaves_an_output_file(files: dict[str, str]) -> None:
    assert not (Path(files["tmp"]) / "o.mcap").exists()
    assert not (Path(files["tmp"]) / "t").exists()


# -- diff's alignment: different periods, different start times ---------------------
def test_diff_aligns_by_run_time_across_periods_and_starts(tmp_path: Path) -> None:
    """A every 5 ms over 1 s, B every 10 ms over 0.8 s from another wall time; both
    f_z = sin(t). Each A message is paired with B's newest at or before it (hold), so
    A's odd 5 ms messages meet B's value 5 ms older: |diff| <= 5 ms * max|cos| = 0.005."""
    a = load(write_run(tmp_path / "a.mcap", period_ms=5, span_s=1.0))
    b = load(write_run(tmp_path / "b.mcap", period_ms=10, span_s=0.8,
                       start_ns=START_NS + 123_456_789_000))
    wide = diff(a, b, ["/estimator/state"], rtol=0.0, atol=0.0051)
    (t,) = wide.topics
    assert wide.ok and t.paired == 161 and t.n_a == 201 and t.n_b == 81  # A's within 0..0.8 s
    assert t.span_s == (0.0, 0.8)
    expected = max(abs(math.sin(k * 0.01 + 0.005) - math.sin(k * 0.01)) for k in range(80))
    assert t.max_abs == pytest.approx(expected, rel=1e-12)
    tight = diff(a, b, ["/estimator/state"], rtol=0.0, atol=1e-9)
    cols = {f.column: f for f in tight.topics[0].fields}
    assert set(cols) == {"f_z", "wrench_2"}
    assert cols["f_z"].first_s == pytest.approx(0.005) and cols["f_z"].count == 80


def test_diff_finds_where_a_step_begins(tmp_path: Path) -> None:
    a = load(write_run(tmp_path / "a.mcap", period_ms=5, span_s=1.0))
    b = load(write_run(tmp_path / "b.mcap", period_ms=5, span_s=1.0,
                       f_z=lambda t: math.sin(t) + (0.25 if t >= 0.5 else 0.0)))
    result = diff(a, b, rtol=1e-6, atol=1e-6)
    (f_z,) = [f for t in result.topics for f in t.fields if f.column == "f_z"]
    assert f_z.first_s == pytest.approx(0.5) and f_z.count == 101
    assert f_z.max_abs == pytest.approx(0.25)
    assert [t.topic for t in result.topics if not t.ok] == ["/estimator/state"]
    same = runner.invoke(app, ["diff", str(a.path), str(a.path)])
    assert same.exit_code == 0, same.output
    step = runner.invoke(app, ["diff", str(a.path), str(b.path), "--plots", str(tmp_path / "f")])
    assert step.exit_code == 1 and "first difference: /estimator/state" in step.stdout
