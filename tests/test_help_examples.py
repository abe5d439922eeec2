"""Every option-value example in the CLI's help (``--set``, ``--scene-set``, ``--rig-set``,
``--fit``; :func:`test_docs_commands.help_examples` finds them) runs with its command, as a
command line a reader could type, in-process through typer's CliRunner in a directory of its
own. Each must end as its command's help says, and the example's value must be in what ran:
the recording's protocol or scene (run, campaign, sweep, limits, reproduce, replay,
resimulate, hil), the rig it ran on (``--rig-set``), the scene the emulator served, the
calibration's bounds, the section III sweep's rows; ``check`` runs nothing, so its example
passes and the same line with the value broken is refused naming the key.

Where the example's key has a value already (the nominal lateral offset is the example's
0.012), another value of the same option comes first on the line, so only the example's own
value, which comes last and wins, gives what the test asserts.

Kept cheap the honest way: every run's ``run.timeout_s`` is short (``--set
run.timeout_s=0.5`` first, so a timeout example's own value wins), a campaign of one
protocol, a sweep of one point, a limits search of two points, the smallest study (the
paper's runs at the nominal scene), one process per pool (``--executor local:1``, ``-j 1``)
and one short recording, made once per module, for replay, resimulate and calibrate.

``--rig-set robot.port=49939`` names the FRI link's port: it runs on the emulator's rig
(``rigs/emulator.toml``) against the emulated KRC served in-process in lockstep (the library
behind ``ffexp emulate``), which sends to that port on the test's own loopback address.
"""

from __future__ import annotations

import csv
import json
import re
import threading
import tomllib
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import pytest
from mcap.reader import make_reader
from test_docs_commands import help_examples
from typer.testing import CliRunner, Result

from ffexp.cli import app

ROOT = Path(__file__).resolve().parents[1]
BESIDE = ("protocols", "data", "rigs", "tests")
STUDY = "tests/data/study_nominal.toml"  # the smallest study: the paper runs, nominal scene
PROTOCOL = "protocols/method1_case1.toml"
SHORT = "run.timeout_s=0.5"
#: Another value of the example's key, given before it (its own value must win).
CONTRAST = {"run.timeout_s": "0.5", "target.mu": "0.004", "target.lateral": "0.02",
            "impact.speed_mps": "0.1"}
#: The test's own loopback address (a KRC sends there; ``--rig-set`` on ``run`` and on
#: ``campaign``, which may run at once, each bind the example's port on their own).
HOST = "127.0.0.41"
RIG_SET_HOSTS = {"run": "127.0.0.41", "campaign": "127.0.0.42"}
#: How ``run`` ends (its help): 0 aligned, 4 timed out without aligning.
RUN_ENDS = (0, 4)

EXAMPLES = [(c, o, v) for c, o, v in help_examples() if o]


# -- what ran -----------------------------------------------------------------------------
def _value(text: str) -> Any:
    return tomllib.loads(f"v = {text}")["v"]


def _at(data: Any, key: str) -> Any:
    for part in key.split("."):
        data = data[part]
    return data


def metadata(path: Path) -> dict[str, dict[str, str]]:
    """The recording's metadata records by name (read without its messages)."""
    with path.open("rb") as f:
        return {m.name: dict(m.metadata) for m in make_reader(f).iter_metadata()}


def recorded(path: Path, where: str, key: str) -> Any:
    """``key`` of the protocol or scene (``where``) a recording says it ran."""
    meta = metadata(path)
    if where == "protocol":
        return _at(json.loads(meta["run"]["protocol_json"]), key)
    (scene,) = {m["scene_json"] for m in meta.values() if "scene_json" in m}
    return _at(json.loads(scene), key)


def _target(command: str, option: str, value: str) -> tuple[str, str, Any]:
    """(protocol or scene, its key, the value) that the example sets."""
    key, _, text = value.partition("=")
    if option == "--scene-set" or command == "emulate":
        return "scene", key, _value(text)
    if key.startswith("scene."):
        return "scene", key.removeprefix("scene."), _value(text)
    return "protocol", key, _value(text)


def _contrast(option: str, value: str) -> list[str]:
    """The same option with another value of the example's key, before it."""
    key = value.partition("=")[0].removeprefix("scene.")
    other = CONTRAST.get(key)
    if other is None or key == "run.timeout_s":  # the short timeout comes first anyway
        return []
    return [option, f"{value.partition('=')[0]}={other}"]


def _mcaps(out: Path) -> list[Path]:
    found = sorted(out.rglob("*.mcap"))
    assert found, f"nothing recorded in {out}"
    return found


def _rows(path: Path) -> list[dict[str, str]]:
    with path.open(newline="") as f:
        return list(csv.DictReader(f))


# -- the module's directory: the repository's files, a campaign, a study, a recording -----
@pytest.fixture(scope="module")
def here(tmp_path_factory: pytest.TempPathFactory) -> Path:
    d = tmp_path_factory.mktemp("help")
    for name in BESIDE:
        (d / name).symlink_to(ROOT / name)
    (d / "one.toml").write_text(
        'name = "one"\ndescription = "one paper run"\n\n[[runs]]\n'
        f'protocol = "{PROTOCOL}"\n')
    return d


@pytest.fixture(scope="module")
def recording(here: Path) -> Path:
    """A run of 2 s whose tool meets the target at about 1.7 s (a faster approach): the
    contact informs target.mu, and every replay of it is short."""
    out = here / "recording"
    result = CliRunner().invoke(app, ["run", PROTOCOL, "--set", "run.timeout_s=2", "--set",
                                      "approach.speed_mps=0.06", "--out", str(out)])
    assert result.exit_code in RUN_ENDS, result.output
    (path,) = out.glob("*.mcap")
    return path.relative_to(here)


# -- one example, its command line and what it must show ----------------------------------
@dataclass
class Case:
    words: list[str]
    ends: tuple[int, ...]
    check: Callable[[Result], None]


def _in_recordings(out: Path, where: str, key: str, want: Any) -> Callable[[Result], None]:
    def check(_result: Result) -> None:
        for path in _mcaps(out):
            assert recorded(path, where, key) == want, (path, where, key)
    return check


def _sweep_rows(out: Path, where: str, key: str, want: Any) -> Callable[[Result], None]:
    def check(result: Result) -> None:
        rows = _rows(out / "results.csv")
        assert rows and not any(r["error"] for r in rows), rows
        for row in rows:  # each row's own recording
            assert recorded(out / row["path"], where, key) == want, (row["path"], key)
    return check


def case(command: str, option: str, value: str, out: Path, rec: Path | None) -> Case:
    if command == "calibrate":
        assert rec is not None and option == "--fit", "a calibrate example of another option"
        return Case(["calibrate", str(rec), option, value, "-j", "1", "--out",
                     str(out / "lab.toml")], (0,), _fit_bounds(out, value))
    where, key, want = _target(command, option, value)
    example = [*_contrast(option, value), option, value]
    short = ["--set", SHORT]
    if command == "run":
        return Case(["run", PROTOCOL, *short, *example, "--out", str(out)], RUN_ENDS,
                    _in_recordings(out, where, key, want))
    if command == "campaign":
        return Case(["campaign", "one.toml", *short, *example, "--no-figures", "--out",
                     str(out)], (0,), _in_recordings(out, where, key, want))
    if command == "sweep":
        return Case(["sweep", PROTOCOL, "--vary", "align.k_ri[3]=0.5", "--executor",
                     "local:1", *short, *example, "--no-figures", "--out", str(out)], (0,),
                    _sweep_rows(out, where, key, want))
    if command == "limits":
        return Case(["limits", PROTOCOL, "--key", "align.k_ri[3]", "--range", "0:4",
                     "--coarse", "2", "--resolution", "4", "--executor", "local:1", *short,
                     *example, "--out", str(out)], (0,), _sweep_rows(out, where, key, want))
    if command == "reproduce":
        return Case(["reproduce", "--config", STUDY, "--executor", "local:1", *short,
                     *example, "--out", str(out)], (0,), _sweep_rows(out, where, key, want))
    if command == "replay":
        assert rec is not None
        return Case(["replay", str(rec), *short, *example, "--out", str(out / "replay.mcap")],
                    (0,), _in_recordings(out, where, key, want))
    if command == "resimulate":
        assert rec is not None
        return Case(["resimulate", str(rec), *example, "--out", str(out / "sim.mcap")], (0,),
                    _in_recordings(out, where, key, want))
    if command == "hil":
        return _hil(option, value, example, out, where, key, want)
    if command == "check":
        return _check(option, value, example, where, key)
    if command == "simulate sweep":
        return Case(["simulate", "sweep", "protocols/sec3_damping.toml", *example, "--out",
                     str(out)], (0,), _section3_rows(out, key, want))
    raise AssertionError(f"`ffexp {command}` has a help example {option} {value} that no "
                         "rule here runs: add one")


def _fit_bounds(out: Path, value: str) -> Callable[[Result], None]:
    from ffexp.calibrate.params import parse_fit
    from ffexp.calibrate.resim import base_scene

    key, _, rng = value.partition("=")
    lo, hi = (float(x) for x in rng.split(":"))
    (default,) = parse_fit([key], base_scene(ROOT / "data/scenes/paper.toml"))
    assert (default.lo, default.hi) != (lo, hi), "the example's bounds are the default ones"

    def check(_result: Result) -> None:
        report = json.loads((out / "lab-report" / "calibration.json").read_text())
        (est,) = report["estimates"]
        assert (est["key"], est["lo"], est["hi"]) == (key, lo, hi), est
        assert (out / "lab.toml").is_file()
    return check


def _hil(option: str, value: str, example: list[str], out: Path, where: str, key: str,
         want: Any) -> Case:
    words = ["hil", "protocols/hil_impact.toml", *example, "--out", str(out)]
    if key == "faults.link_lost_at_s":  # the carrier holds then: exit 3, the cause said
        def held(result: Result) -> None:
            assert re.search(rf"carrier held at {want:.3f} s: carrier link lost",
                             result.output), result.output
        return Case(words, (3,), held)
    if key.startswith("impact."):
        def impact(_result: Result) -> None:
            (path,) = _mcaps(out)
            meta = metadata(path)["hil_impact"]
            assert float(meta[key.removeprefix("impact.")]) == want, meta
        return Case(words, (0,), impact)
    return Case(words, (0,), _in_recordings(out, where, key, want))


def _check(option: str, value: str, example: list[str], where: str, key: str) -> Case:
    """``check`` runs nothing: the example passes, and the same line with the example's
    value broken is refused, naming the key (so the value reached the checks)."""
    broken = ["check", PROTOCOL, *example[:-1], value.partition("=")[0] + "=x"]

    def ok(result: Result) -> None:
        assert result.output.startswith(f"ok: {PROTOCOL}: run protocol"), result.output
        refused = CliRunner().invoke(app, broken)
        assert refused.exit_code == 2, refused.output
        (line,) = refused.stderr.strip().splitlines()
        assert line.startswith("error: ") and f"{key}: " in line, line
    return Case(["check", PROTOCOL, *example], (0,), ok)


def _section3_rows(out: Path, key: str, want: Any) -> Callable[[Result], None]:
    def check(_result: Result) -> None:
        assert key == "sweep.values"
        (summary,) = out.glob("*_summary.csv")
        assert [float(r["value"]) for r in _rows(summary)] == [float(x) for x in want]
    return check


# -- the tests ----------------------------------------------------------------------------
RUNNABLE = [e for e in EXAMPLES if e[1] != "--rig-set"]
RIG_SETS = [e for e in EXAMPLES if e[1] == "--rig-set"]
NEEDS_RECORDING = ("replay", "resimulate", "calibrate")


def test_the_help_has_examples_for_every_command_that_runs_a_protocol() -> None:
    commands = {c for c, _o, _v in EXAMPLES}
    assert {"run", "campaign", "sweep", "limits", "reproduce", "replay", "resimulate",
            "calibrate", "emulate", "hil", "check", "simulate sweep"} <= commands
    assert len(EXAMPLES) >= 30


@pytest.mark.slow
@pytest.mark.parametrize(("command", "option", "value"), RUNNABLE,
                         ids=[f"{c} {o} {v}" for c, o, v in RUNNABLE])
def test_every_help_example_runs_with_its_command(
        command: str, option: str, value: str, here: Path, tmp_path: Path,
        request: pytest.FixtureRequest, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.chdir(here)
    if command == "emulate":
        _emulate(option, value, monkeypatch)
        return
    rec = request.getfixturevalue("recording") if command in NEEDS_RECORDING else None
    c = case(command, option, value, tmp_path / "out", rec)
    (tmp_path / "out").mkdir()  # the commands that write one file write it there
    result = CliRunner().invoke(app, c.words)
    line = "ffexp " + " ".join(c.words)
    assert result.exit_code in c.ends, f"`{line}`: exit {result.exit_code}\n{result.output}"
    c.check(result)


def _emulate(option: str, value: str, monkeypatch: pytest.MonkeyPatch) -> None:
    """``ffexp emulate`` for 0.05 s with nobody answering (the KRC sends to a free port of
    the test's address; how many cycles that is depends on the machine's load): it ends by
    itself, and the scene it built its world from has the example's value."""
    from emulator_process import free_udp_port

    import drivers.emulate.session as session

    served: list[Any] = []

    class Spy(session.EmulatedRig):
        def open(self) -> None:
            super().open()
            served.append(self.world)

    monkeypatch.setattr(session, "EmulatedRig", Spy)
    _where, key, want = _target("emulate", option, value)
    words = ["emulate", "--remote", f"{HOST}:{free_udp_port()}", "--netft-port", "0",
             "--duration", "0.05", *_contrast(option, value), option, value]
    result = CliRunner().invoke(app, words)
    assert result.exit_code == 0, result.output
    assert re.search(r"^ffexp emulate: cycles \d+, ", result.stderr, re.M), result.stderr
    (world,) = served
    assert _at_object(world.scene, key) == want


def _at_object(obj: Any, key: str) -> Any:
    for part in key.split("."):
        obj = getattr(obj, part)
    return obj


@contextmanager
def emulated_krc(host: str, port: int) -> Iterator[Any]:
    """The KRC of ``ffexp emulate --pacing lockstep``, in-process, sending from ``host`` to
    ``port`` there; its Net F/T box on a free port of the same address."""
    from drivers.description.scene import load_scene
    from drivers.emulate.session import EmulatedRig, EmulatedRigSettings

    settings = EmulatedRigSettings(
        scene=load_scene(ROOT / "data/scenes/paper.toml"), remote=(host, port), host=host,
        port=0, netft_port=0, pacing="lockstep", seed=1)
    stop = threading.Event()
    with EmulatedRig(settings) as rig:
        errors: list[BaseException] = []

        def serve() -> None:
            try:
                rig.serve(stop.is_set)
            except BaseException as exc:
                errors.append(exc)

        thread = threading.Thread(target=serve, daemon=True)
        thread.start()
        try:
            yield rig
        finally:
            stop.set()
            thread.join(30)
        assert not thread.is_alive() and not errors, errors


@pytest.mark.slow
@pytest.mark.parametrize(("command", "option", "value"), RIG_SETS,
                         ids=[f"{c} {o} {v}" for c, o, v in RIG_SETS])
def test_rig_set_reaches_the_fri_link(command: str, option: str, value: str, here: Path,
                                      tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    """``--rig-set robot.port=49939`` on the emulator's rig: the emulated KRC sends to that
    port only, so the run gets its measurements only when the value reached the link."""
    monkeypatch.chdir(here)
    key, _, text = value.partition("=")
    assert key == "robot.port", "a --rig-set example of another field: add its rule"
    port = int(text)
    assert port != 49938, "the example's port is the rig's own"
    out = tmp_path / "out"
    host = RIG_SET_HOSTS[command]
    with emulated_krc(host, port) as rig:
        assert rig.netft is not None
        where = ["--rig", "rigs/emulator.toml", "--rig-set", f"robot.robot_ip='{host}'",
                 "--rig-set", f"robot.bind_host='{host}'", "--rig-set", f"ft.host='{host}'",
                 "--rig-set", f"ft.port={rig.netft.address[1]}"]
        if command == "run":
            words = ["run", PROTOCOL, *where, "--set", SHORT, option, value, "--out", str(out)]
            ends: tuple[int, ...] = RUN_ENDS
        else:
            words = ["campaign", "one.toml", *where, "--set", SHORT, option, value,
                     "--no-figures", "--out", str(out)]
            ends = (0,)
        result = CliRunner().invoke(app, words)
    assert result.exit_code in ends, result.output
    (path,) = _mcaps(out)
    run = metadata(path)["run"]
    assert json.loads(run["rig_json"])["robot"]["port"] == port
    assert re.match(r"cycles [1-9]\d*, sent \d+, answered [1-9]", rig.summary()), rig.summary()
