"""``ffexp simulate`` through typer's CliRunner and as a subprocess."""

from __future__ import annotations

import csv
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.contact1dof import COLUMNS, ContactParams, simulate

ROOT = Path(__file__).resolve().parents[1]
runner = CliRunner()


def run_ffexp(*args: str, cwd: Path) -> subprocess.CompletedProcess[str]:
    """The installed CLI in a child process, as a user would run it."""
    return subprocess.run(
        [sys.executable, "-c", "from ffexp.cli import main; main()", *args],
        cwd=cwd, capture_output=True, text=True, timeout=300, check=False,
    )


def test_help_lists_commands() -> None:
    result = runner.invoke(app, ["--help"])
    assert result.exit_code == 0
    assert "simulate" in result.stdout


def test_contact_1dof_csv_matches_model(tmp_path: Path) -> None:
    out = tmp_path / "x.csv"
    args = ["--m-ri", "11", "--m-t", "9", "--k-ri", "300", "--b-ri", "40", "--csv", str(out)]
    result = runner.invoke(app, ["simulate", "contact-1dof", *args])
    assert result.exit_code == 0, result.stderr
    with out.open() as fh:
        header = next(csv.reader(fh))
    assert tuple(header) == COLUMNS == ("t", "x_i", "v_i", "x_t", "v_t", "p", "F_c")
    data = np.loadtxt(out, delimiter=",", skiprows=1)
    params = ContactParams(m_ri=11, m_t=9, k_ri=300, b_ri=40)
    expected = simulate(params, 3.0, 1e-3).table()
    assert data.shape == expected.shape
    np.testing.assert_allclose(data, expected, rtol=1e-8, atol=1e-12)
    # the file is self-consistent with the model's definitions
    _t, x_i, v_i, x_t, v_t, p, f_c = data.T
    np.testing.assert_allclose(p, x_i - x_t, atol=1e-9)
    np.testing.assert_allclose(f_c, 250.0 * p + 20.0 * (v_i - v_t), rtol=1e-7, atol=1e-7)
    assert "peak F_c" in result.stdout and "settling time" in result.stdout


def test_contact_1dof_summary_reports_break() -> None:
    result = runner.invoke(app, ["simulate", "contact-1dof", "--m-ri", "60", "--m-t", "15"])
    assert result.exit_code == 0
    assert "contact broke: yes" in result.stdout
    result = runner.invoke(app, ["simulate", "contact-1dof", "--m-ri", "1.5", "--m-t", "15"])
    assert "contact broke: no" in result.stdout


def test_contact_1dof_rejects_bad_option() -> None:
    result = runner.invoke(app, ["simulate", "contact-1dof", "--m-t", "0"])
    assert result.exit_code == 2
    assert result.stderr.strip().count("\n") == 0
    assert "--m-t" in result.stderr
    assert "Traceback" not in result.stderr + result.stdout


@pytest.mark.parametrize(
    ("args", "flag"),
    [
        (["--dt", "0"], "--dt"),
        (["--dt", "5"], "--dt"),
        (["--duration", "-1"], "--duration"),
        (["--duration", "1000", "--dt", "1e-6"], "--dt"),
    ],
)
def test_contact_1dof_bad_time_grid_names_the_option(args: list[str], flag: str) -> None:
    result = runner.invoke(app, ["simulate", "contact-1dof", *args])
    assert result.exit_code == 2
    assert result.stderr.strip().count("\n") == 0
    assert result.stderr.startswith(f"error: options: {flag}: ")
    assert "Traceback" not in result.stderr + result.stdout


def test_sweep_writes_figures_and_csv(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        ["simulate", "sweep", str(ROOT / "protocols/sec3_stiffness.toml"), "--out", str(tmp_path)],
    )
    assert result.exit_code == 0, result.stderr
    png = tmp_path / "sec3_stiffness.png"
    assert png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert (tmp_path / "sec3_stiffness.svg").read_text().lstrip().startswith("<?xml")
    with (tmp_path / "sec3_stiffness.csv").open() as fh:
        rows = list(csv.reader(fh))
    assert rows[0] == ["k_ri", *COLUMNS]
    values = sorted({float(r[0]) for r in rows[1:]})
    assert values == [0.0, 100.0, 300.0, 1000.0, 3000.0]
    assert len(rows) - 1 == 5 * 3001
    with (tmp_path / "sec3_stiffness_summary.csv").open() as fh:
        summary = list(csv.DictReader(fh))
    broke = [s["contact_broke"] for s in summary]
    assert broke[0] == "false"
    assert broke[-1] == "true"


def test_set_override_changes_the_sweep(tmp_path: Path) -> None:
    result = runner.invoke(
        app,
        [
            "simulate", "sweep", str(ROOT / "protocols/sec3_damping.toml"), "--out", str(tmp_path),
            "--set", "sweep.values=[10, 30]", "--set", "time.duration_s=1.0",
        ],
    )
    assert result.exit_code == 0, result.stderr
    with (tmp_path / "sec3_damping_summary.csv").open() as fh:
        summary = list(csv.DictReader(fh))
    assert [float(s["b_ri"]) for s in summary] == [10.0, 30.0]
    data = np.loadtxt(tmp_path / "sec3_damping.csv", delimiter=",", skiprows=1)
    assert data[:, 1].max() == pytest.approx(1.0)


BAD_PROTOCOLS = {
    "unknown key": ('[sweep]\nparameter = "k_ri"\nvalues = [1]\nvaluez = [2]\n', "sweep.valuez"),
    "wrong type": ('[sweep]\nparameter = "k_ri"\nvalues = "many"\n', "sweep.values"),
    "bad parameter": ('[sweep]\nparameter = "colour"\nvalues = [1]\n', "sweep.parameter"),
    "negative mass": (
        '[model]\nm_t = -1\n[sweep]\nparameter = "k_ri"\nvalues = [1]\n',
        "model.m_t",
    ),
    "value breaks model": ('[sweep]\nparameter = "b_ri"\nvalues = [10, -5]\n', "sweep.values"),
    "missing table": ('name = "x"\n', "sweep"),
    "not toml": ("[sweep\nparameter =", "invalid TOML"),
}


@pytest.mark.parametrize("case", sorted(BAD_PROTOCOLS))
def test_bad_protocol_one_line_exit_2(tmp_path: Path, case: str) -> None:
    text, field = BAD_PROTOCOLS[case]
    path = tmp_path / "bad.toml"
    if "name" not in text:
        text = 'name = "bad"\n' + text
    path.write_text(text)
    result = runner.invoke(app, ["simulate", "sweep", str(path), "--out", str(tmp_path / "o")])
    assert result.exit_code == 2
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, result.stderr
    assert str(path) in lines[0] and field in lines[0]
    assert not (tmp_path / "o").exists()


def test_missing_protocol_and_bad_set(tmp_path: Path) -> None:
    result = runner.invoke(app, ["simulate", "sweep", str(tmp_path / "nope.toml")])
    assert result.exit_code == 2
    assert result.stderr.strip() == f"error: {tmp_path / 'nope.toml'}: file not found"
    result = runner.invoke(
        app,
        ["simulate", "sweep", str(ROOT / "protocols/sec3_damping.toml"), "--set", "sweep.values"],
    )
    assert result.exit_code == 2
    assert "--set" in result.stderr and "dotted.key=value" in result.stderr


def test_subprocess_sweep_and_bad_file(tmp_path: Path) -> None:
    proto = ROOT / "protocols/sec3_mass_ratio.toml"
    done = run_ffexp("simulate", "sweep", str(proto), "--out", "out", cwd=tmp_path)
    assert done.returncode == 0, done.stderr
    assert (tmp_path / "out/sec3_mass_ratio.png").stat().st_size > 10_000
    assert "sec3_mass_ratio.png" in done.stdout
    bad = tmp_path / "bad.toml"
    bad.write_text('name = "b"\n[sweep]\nparameter = "k_ri"\nvalues = [1]\ncolour = 3\n')
    done = run_ffexp("simulate", "sweep", str(bad), cwd=tmp_path)
    assert done.returncode == 2
    assert done.stderr.strip() == f"error: {bad}: sweep.colour: unknown key"
    assert "Traceback" not in done.stderr
