"""Emulated devices served from the simulated world: the KRC (FRI 1.x), the Net F/T box,
the camera and the in-process lockstep robot; :mod:`drivers.emulate.session` assembles and
serves them as one emulated rig (``ffexp emulate``).

This package combines the simulated world (:mod:`drivers.world`) and back-ends
(:mod:`drivers.sim`, :mod:`drivers.fri`,
:mod:`drivers.netft`, :mod:`drivers.net`); no back-end imports it.
"""
