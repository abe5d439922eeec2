"""No compile inside a loop: every compiled kernel declares its signatures, is loaded
before the robot connects (``ffexp.compiled.load_kernels``), and none compiles during a
run (a new argument type is a TypeError, not a compile stalling a real-time cycle)."""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from numba.core.registry import CPUDispatcher

from drivers.base import signatures
from ffexp import compiled
from ffexp.experiment import run_file
from ffexp.rig_choice import RigChoice

ROOT = Path(__file__).resolve().parents[1]
_DECORATOR = re.compile(r"^\s*@(?:numba\.)?(?:njit|jit|vectorize|guvectorize|cfunc)\b",
                        re.MULTILINE)


def _kernel_modules() -> tuple[str, ...]:
    return (*signatures.KERNEL_MODULES, *compiled.KERNEL_MODULES)


def _decorated_sources() -> dict[str, int]:
    """The modules of ffexp and drivers that compile code (numba), by dotted name, and
    how many compiled functions each defines, read from the sources."""
    found = {}
    for package in ("ffexp", "drivers"):
        for path in sorted((ROOT / package).rglob("*.py")):
            n = len(_DECORATOR.findall(path.read_text()))
            if n:
                found[".".join(path.relative_to(ROOT).with_suffix("").parts)] = n
    return found


def _dispatchers() -> dict[str, Any]:
    """Every compiled function of the kernels modules (loaded), by qualified name."""
    out = {}
    for module in compiled.load_kernels():
        for name, value in vars(module).items():
            if isinstance(value, CPUDispatcher) and value.py_func.__module__ == module.__name__:
                out[f"{module.__name__}.{name}"] = value
    return out


def _signatures() -> dict[str, int]:
    return {name: len(d.signatures) for name, d in _dispatchers().items()}


def test_every_compiling_module_is_loaded_before_the_loop() -> None:
    """A module that compiles code is one ``load_kernels`` imports, and each of its
    compiled functions is a dispatcher found there (a kernel added elsewhere, or one not
    at module level, fails here)."""
    sources = _decorated_sources()
    assert set(sources) == set(_kernel_modules())
    found = _dispatchers()
    for module, n in sources.items():
        assert sum(name.rsplit(".", 1)[0] == module for name in found) == n, module


def test_every_kernel_declares_its_signatures_and_never_compiles() -> None:
    """Each dispatcher was compiled (or loaded) for its declared signatures when its
    module was imported, and numba's compile is off on every one of them."""
    found = _dispatchers()
    assert len(found) >= 40
    for name, dispatcher in found.items():
        assert not dispatcher._can_compile, f"{name}: declare its signatures (@njit([...]))"
        assert dispatcher.signatures, name


def test_an_undeclared_argument_type_is_a_type_error_not_a_compile() -> None:
    from drivers.world import kernels

    before = len(kernels.torques.signatures)
    with pytest.raises(TypeError):
        kernels.torques(np.zeros(3, np.float32), np.zeros(3), np.zeros(3))
    assert len(kernels.torques.signatures) == before
    tau = np.array([1.0, 2.0, 3.0])
    kernels.torques(tau, np.full(3, 0.5), np.ones(3))  # the declared one still works
    assert tau.tolist() == [0.5, 1.5, 2.5]


@pytest.mark.slow
@pytest.mark.parametrize(("protocol", "driver", "timeout_s"), [
    ("method1_case1", None, 4.2), ("sixdof_method1", None, 4.2),
    ("method1_case1", "ur-sim", 4.2), ("method1_case1", "franka-sim", 5.0)])
def test_a_whole_run_adds_no_compiled_signature(protocol: str, driver: str | None,
                                                 timeout_s: float, tmp_path: Path) -> None:
    """A run on the simulator (paper Method I, 6-DOF, the UR and Franka back-ends) makes
    contact and ends, every kernel having the signatures it had before it connected."""
    before = _signatures()
    result = run_file(ROOT / f"protocols/{protocol}.toml", [f"run.timeout_s={timeout_s}"],
                      rig=RigChoice(driver=driver), out_dir=tmp_path, lean=True)
    assert result.outcome.contacts >= 1
    assert _signatures() == before
