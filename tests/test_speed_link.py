"""LinkWindow keeps running counts (no array work per lockstep cycle): same rates as by hand."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.fri.link import LinkWindow


def _direct(answered: list[bool], latency: list[float], size: int) -> tuple[float, ...]:
    a = np.array(answered[-size:], dtype=bool)
    lat = np.array(latency[-size:])[a]
    if a.size == 0:
        return 0.0, 0.0, 0.0, 0.0
    k = int(a.sum())
    rate = k / a.size
    return rate, float(lat.mean()) if k else 0.0, float(lat.std()) if k > 1 else 0.0, 1.0 - rate


def test_rates_equal_the_direct_computation_over_random_histories() -> None:
    rng = np.random.default_rng(5)
    for trial in range(20):
        size = int(rng.integers(3, 12))
        w = LinkWindow(size)
        answered: list[bool] = []
        latency: list[float] = []
        timed = trial % 2 == 0  # half the histories in lockstep (all latencies zero)
        for _ in range(60):
            if rng.random() < 0.05:
                w.reset()
                answered, latency = [], []
            ans = bool(rng.random() < 0.8)
            lat = float(rng.uniform(0.0, 0.003)) if timed and rng.random() < 0.5 else 0.0
            w.add(ans, lat)
            answered.append(ans)
            latency.append(lat if ans else 0.0)
            got, want = w.rates(), _direct(answered, latency, size)
            assert got[0] == want[0] and got[3] == want[3]  # counts: exact
            assert got[1:3] == pytest.approx(want[1:3], rel=1e-12, abs=1e-18)
            if not timed:
                assert got == want
        w.fill()
        assert w.rates() == (1.0, 0.0, 0.0, 0.0)
