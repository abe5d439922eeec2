"""The ``sim`` back-end: the simulated world's F/T sensor and target tracker as rig
entries (:mod:`drivers.sim.backend`), for any robot that offers the world
(``[ft] type = "sim"``, ``[tracker] type = "sim"``). The world itself is the neutral
:mod:`drivers.world`; the simulated robots are their families' (the ``sim`` robot is
the LWR4+ family's lockstep KRC, :mod:`drivers.fri.emulate.lockstep`).
"""
