"""A second robot as a micro-gravity emulator: the target's mock-up on a carrier robot's
flange behind its own F/T sensor, the target's free flight integrated from the measured
wrench and commanded as the carrier's pose (``docs/hil.md``). Pure physics, no I/O:
the free body (:mod:`~drivers.carrier.body`), the loop and the carrier's servo
(:mod:`~drivers.carrier.loop`), the compensation (:mod:`~drivers.carrier.passivity`)
and a simulated impact (:mod:`~drivers.carrier.bench`).
"""
