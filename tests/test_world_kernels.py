"""The world's compiled arithmetic (drivers/world/kernels.py) against the numpy form it
replaces, bit for bit, on random inputs (a recording must not change by one ulp)."""

from __future__ import annotations

from typing import Any

import numpy as np
import pytest

from drivers.base.types import FtSamples
from drivers.description.scene import FtSensorSettings
from drivers.world.ftsensor import FtSensorModel


def _bits(a: Any) -> bytes:
    return np.ascontiguousarray(a).tobytes()


def _reference(model: FtSensorModel) -> None:
    """Make ``model`` compute its blocks with its numpy form (``_delayed``, ``_block``)
    where it would call the compiled block."""

    def block(white: Any, i: int, raw: Any, buf: Any, dn: int, drift: Any, consts: Any,
              tared: bool, out: Any, row_over: Any) -> int:
        n = raw.shape[0]
        x = model._delayed(raw) if dn else raw  # the same buffer, shifted the same way
        w, status = model._block(white[i:i + n], x, drift)
        out[:] = w
        row_over[:] = status != 0
        return int(np.count_nonzero(status))

    model._ft_block = block  # type: ignore[method-assign]


def _pair(seed: int, settings: FtSensorSettings, r: Any) -> tuple[FtSensorModel, FtSensorModel]:
    fast = FtSensorModel(settings, np.random.default_rng(seed), r)
    ref = FtSensorModel(settings, np.random.default_rng(seed), r)
    _reference(ref)
    return fast, ref


def _same(a: FtSamples, b: FtSamples) -> None:
    assert _bits(a.wrench) == _bits(b.wrench)
    assert _bits(a.status) == _bits(b.status)
    assert _bits(a.time_ns) == _bits(b.time_ns)
    assert _bits(a.seq) == _bits(b.seq)


#: a resolution so fine that the counts' rounding keeps every bit (2**-60: a value
#: times 2**60 is an integer already), so a product summed otherwise would show
FINE = 2.0**-60


@pytest.mark.parametrize(("delay_s", "resolution"),
                         [(0.0, FINE), (0.001, FINE), (0.003, FINE), (0.001, None)])
def test_ft_block_is_the_numpy_form(delay_s: float, resolution: float | None) -> None:
    """Blocks of changing sizes (one row: numpy's own path), loads far beyond the gauge
    range now and then (the clip and the status), a tare, a replaced bias, a random tool
    offset (the transform's products): every sample and the model's state the same."""
    rng = np.random.default_rng(7)
    for trial in range(6):
        settings = FtSensorSettings(delay_s=delay_s) if resolution is None else \
            FtSensorSettings(delay_s=delay_s, resolution=(resolution, resolution))
        r = rng.normal(size=3) * 0.1 if trial else np.array([0.0, 0.0, -0.12])
        fast, ref = _pair(trial, settings, r)
        t_ns = 0
        for block in range(300):
            n = int(rng.choice([5, 5, 5, 1, 2, 3, 8, 13]))
            raw = rng.normal(size=(n, 6)) * np.array([20.0, 20.0, 40.0, 1.0, 1.0, 1.0])
            if block % 17 == 3:  # some values saturate the gauges
                raw[rng.integers(n), rng.integers(6)] = 1e3 * rng.choice([-1.0, 1.0])
            if block == 100:  # a software tare
                fast.tare_offset = fast.tare_offset + fast.last_wrench
                ref.tare_offset = ref.tare_offset + ref.last_wrench
            if block == 200:  # a new bias object
                fast.bias = fast.bias + 0.25
                ref.bias = ref.bias + 0.25
            _same(fast.process(raw, t_ns), ref.process(raw.copy(), t_ns))
            t_ns += n * fast.period_ns
        assert _bits(fast.drift) == _bits(ref.drift)
        assert _bits(fast.last_wrench) == _bits(ref.last_wrench)
        assert fast.seq == ref.seq


def test_ft_block_saturates_and_flags_rows() -> None:
    """A reading beyond the range comes out clipped to it (then rounded) with the
    saturation bit on its row only."""
    settings = FtSensorSettings(noise_std=(0.0, 0.0), bias_std=(0.0, 0.0),
                                drift_density=(0.0, 0.0), delay_s=0.0)
    model = FtSensorModel(settings, np.random.default_rng(0), np.zeros(3))
    raw = np.zeros((4, 6))
    raw[2, 1] = -500.0  # parent on child: the wrench on the tool is +500 N
    out = model.process(raw, 0)
    assert out.wrench[2, 1] == settings.range[1]
    assert out.status.tolist() == [0, 0, 0x00020000, 0]
    assert not out.wrench[[0, 1, 3]].any()
