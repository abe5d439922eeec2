"""``ffexp limits``: the bisection on synthetic outcome functions (converges to the known
boundary at the stated resolution, repeatable, every bracket found), rays in the plane,
and the command: its runs are cached, so the same call twice gives the same answer."""

from __future__ import annotations

import json
import math
from pathlib import Path

import pytest
from typer.testing import CliRunner

from ffexp.cli import app
from ffexp.sweeps import limits
from ffexp.sweeps.worker import RUNS_DIR

ROOT = Path(__file__).resolve().parents[1]
P1 = ROOT / "protocols/method1_case1.toml"
cli = CliRunner()


def window(lo: float, hi: float) -> limits.Evaluate:
    """Aligns strictly inside (lo, hi): a lower and an upper limit."""
    return lambda pts: [1.0 if lo < p[0] < hi else 0.0 for p in pts]


@pytest.mark.parametrize(("lo", "hi", "res"), [(0.47, 2.13, 0.01), (0.2, 1.5, 0.05),
                                                (1.01, 3.9, 0.001)])
def test_bisection_brackets_each_limit_at_the_resolution(lo: float, hi: float, res: float
                                                         ) -> None:
    calls: list[int] = []

    def ev(pts: list[limits.Coords]) -> list[float]:
        calls.append(len(pts))
        return window(lo, hi)(pts)

    r = limits.search(ev, limits.line(0.0, 4.0), coarse=5, resolution=[res])
    rows = limits.describe(r, ["k"])
    assert [row["kind"] for row in rows] == ["lower", "upper"]
    for row, edge in zip(rows, (lo, hi), strict=True):
        a, b = row["k from"], row["k to"]
        assert a <= edge <= b and b - a <= res * (1 + 1e-9)
        assert abs(row["k"] - edge) <= res / 2 + 1e-12
    lower, upper = r.transitions
    assert (lower.lo_fraction, lower.hi_fraction) == (0.0, 1.0)
    assert (upper.lo_fraction, upper.hi_fraction) == (1.0, 0.0)
    # rounds: the coarse grid, then one round per halving (both brackets together)
    halvings = math.ceil(math.log2(1.0 / res))
    assert len(calls) == 1 + halvings
    assert max(calls[1:]) == 2
    again = limits.search(window(lo, hi), limits.line(0.0, 4.0), coarse=5, resolution=[res])
    assert limits.describe(again, ["k"]) == rows


def test_every_change_is_bracketed_and_none_when_constant() -> None:
    def ev(pts: list[limits.Coords]) -> list[float]:  # aligns in two windows
        return [1.0 if (0.5 < p[0] < 1.2 or 2.3 < p[0] < 3.1) else 0.0 for p in pts]

    r = limits.search(ev, limits.line(0.0, 4.0), coarse=9, resolution=[0.02])
    kinds = [row["kind"] for row in limits.describe(r, ["k"])]
    assert kinds == ["lower", "upper", "lower", "upper"]
    flat = limits.search(lambda pts: [1.0] * len(pts), limits.line(0.0, 1.0), coarse=3,
                         resolution=[0.1])
    assert flat.transitions == [] and len(flat.evaluated) == 3


def test_seed_fractions_decide_by_majority() -> None:
    """Two of three seeds align above 1.0, one of three below: the limit is at 1.0."""
    r = limits.search(lambda pts: [2 / 3 if p[0] > 1.0 else 1 / 3 for p in pts],
                      limits.line(0.0, 2.0), coarse=3, resolution=[0.01])
    (tr,) = r.transitions
    assert tr.rising and tr.lo[0] <= 1.0 <= tr.hi[0]


def test_rays_find_a_circular_boundary() -> None:
    """Aligns inside a circle of radius 1 around (2, 3): every ray's bracket holds it."""
    def ev(pts: list[limits.Coords]) -> list[float]:
        return [1.0 if math.hypot(p[0] - 2, p[1] - 3) < 1.0 else 0.0 for p in pts]

    segs = limits.rays([(0.0, 4.0), (1.0, 5.0)], 12)
    assert len(segs) == 12 and all(s.start == (2.0, 3.0) for s in segs)
    r = limits.search(ev, segs, coarse=5, resolution=[0.01, 0.01])
    assert len(r.transitions) == 12
    for tr in r.transitions:
        assert not tr.rising  # aligns inside, not outside
        assert math.hypot(tr.lo[0] - 2, tr.lo[1] - 3) <= 1.0 <= math.hypot(
            tr.hi[0] - 2, tr.hi[1] - 3)
        assert abs(tr.hi[0] - tr.lo[0]) <= 0.01 + 1e-9 and abs(tr.hi[1] - tr.lo[1]) <= 0.01 + 1e-9


def test_cli_limits_is_repeatable_and_caches_its_runs(tmp_path: Path) -> None:
    out = tmp_path / "lim"
    args = ["limits", str(P1), "--key", "align.k_ri[3]", "--range", "0:2", "--coarse", "3",
            "--set", "run.timeout_s=0.4", "--executor", "local:1", "--out", str(out)]
    first = cli.invoke(app, args)
    assert first.exit_code == 0, first.output
    runs = sorted(p.name for p in (out / RUNS_DIR).iterdir())
    saved = json.loads((out / "limits.json").read_text())
    assert saved["resolution"] == [2 / 16] and len(runs) >= 3
    second = cli.invoke(app, args)
    assert second.exit_code == 0
    assert second.stdout == first.stdout  # the same answer
    assert sorted(p.name for p in (out / RUNS_DIR).iterdir()) == runs  # nothing new ran
    assert json.loads((out / "limits.json").read_text()) == saved
    assert (out / "figures" / "limits.png").is_file()


@pytest.mark.parametrize(("extra", "needle"), [
    (["--key", "align.k_ri[3]"], "--range"),
    (["--key", "align.k_ri[3]", "--range", "2:1"], "empty range"),
    (["--key", "align.nope", "--range", "0:1"], "align.nope"),
    (["--key", "align.k_ri[3]", "--range", "0:1", "--resolution", "0"], "--resolution"),
    (["--key", "align.k_ri[3]", "--range", "0:1", "--executor", "ray:127.0.0.1:1"],
     "not reachable"),
])
def test_limits_bad_input(tmp_path: Path, extra: list[str], needle: str) -> None:
    res = cli.invoke(app, ["limits", str(P1), *extra, "--out", str(tmp_path / "x")])
    assert res.exit_code == 2, res.output
    err = res.stderr.strip().splitlines()
    assert len(err) == 1 and err[0].startswith("error: ") and needle in err[0]
    assert not (tmp_path / "x").exists()


def test_max_breaks_makes_breaking_runs_count_as_not_aligning() -> None:
    from ffexp.sweeps.keys import parse_key
    from ffexp.sweeps.plan import Target
    from ffexp.sweeps.searches import LimitSearch

    t = Target(P1)
    key = [parse_key("align.k_ri[3]")]
    plain = LimitSearch(t, key, [(0.0, 1.0)], [1], [0.1])
    strict = LimitSearch(t, key, [(0.0, 1.0)], [1], [0.1], max_breaks=1)
    rows = [{"aligned": True, "contact_breaks": 0}, {"aligned": True, "contact_breaks": 3},
            {"aligned": False, "contact_breaks": 0},
            {"aligned": True, "contact_breaks": 0, "error": "SimulationError: x"}]
    assert [plain.aligns(r) for r in rows] == [True, True, False, False]
    assert [strict.aligns(r) for r in rows] == [True, False, False, False]
    res = cli.invoke(app, ["limits", str(P1), "--key", "align.k_ri[3]", "--range", "0:1",
                           "--max-breaks", "-1"])
    assert res.exit_code == 2 and "--max-breaks" in res.stderr


def test_a_run_aligns_by_its_outcome_and_each_limit_names_the_outcome_beyond_it() -> None:
    """The outcome rule decides, not the aligned flag (a momentary seat in a run whose
    contact keeps breaking does not align), and a lower limit carries the outcome below
    it, an upper one the outcome above it."""
    from ffexp.sweeps import limits
    from ffexp.sweeps.keys import parse_key
    from ffexp.sweeps.plan import Target
    from ffexp.sweeps.searches import LimitSearch

    s = LimitSearch(Target(P1), [parse_key("align.k_ri[3]")], [(0.0, 4.0)], [1], [1.0])
    assert s.aligns({"aligned": True, "outcome": "contact kept breaking"}) is False
    assert s.aligns({"aligned": True, "outcome": "aligned"}) is True
    broke_then_seated = {"aligned": True, "outcome": "aligned", "breaks_after_transient": 3}
    assert s.aligns(broke_then_seated) is False
    said = {0.0: "held contact, did not slide", 1.0: "aligned", 2.0: "aligned",
            3.0: "aligned", 4.0: "aligned"}  # at 4: seated after its contact kept breaking
    s.rows = [{"align.k_ri[3]": k, "outcome": o, "aligned": True,
               "breaks_after_transient": 3 if k == 4.0 else 0} for k, o in said.items()]
    s.result = limits.search(
        lambda pts: [float(s.aligns(next(r for r in s.rows if r["align.k_ri[3]"] == p[0])))
                     for p in pts],
        s.segments(), coarse=5, resolution=[1.0])
    found = {r["kind"]: r["beyond"] for r in s.limits_rows()}
    assert found == {"lower": "held contact, did not slide",
                     "upper": "contact kept breaking, then aligned"}
