"""Many runs of a protocol: sweeps, gain-limit search and the paper check (docs/sweeps.md).

A run is fully determined by (protocol, overrides, seed) and the in-process
simulator is deterministic, so a run has an id (:func:`ffexp.sweeps.keys.run_id`)
and its result is computed once: :mod:`~ffexp.sweeps.engine` runs jobs on any
:class:`concurrent.futures.Executor` (a process pool, or Ray:
:mod:`~ffexp.sweeps.executors`) and skips ids already done. The Section III (1-DOF)
model's own parameter sweeps are :mod:`ffexp.contact1dof.sweep`.
"""
