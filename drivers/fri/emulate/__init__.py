"""The LWR4+ family's emulated side: the KRC2 LR on the simulated world.

- :mod:`~drivers.fri.emulate.krc` — the KRC's behaviour on the world (FRI commands to the
  world's arm commands: its Cartesian impedance law with the wrench feed-forward, the
  command delay, software limit switches);
- :mod:`~drivers.fri.emulate.server` — the KRC over UDP (``ffexp emulate --robot lwr4``);
- :mod:`~drivers.fri.emulate.lockstep` — the ``sim`` robot: the same KRC in-process;
- :mod:`~drivers.fri.emulate.served` — the server as the emulated rig serves it.
"""
