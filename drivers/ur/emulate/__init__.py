"""The UR family's emulated side: a UR e-Series controller on the simulated world.

- :mod:`~drivers.ur.emulate.control` — force mode and the pose servo on the world's arm
  (the controller's law);
- :mod:`~drivers.ur.emulate.controller` — ffexp's URScript program on it, through its
  registers;
- :mod:`~drivers.ur.emulate.rtde_server`, :mod:`~drivers.ur.emulate.server` — the
  controller over RTDE (``ffexp emulate --robot ur5e``);
- :mod:`~drivers.ur.emulate.lockstep` — the ``ur-sim`` robot: the same program in-process;
- :mod:`~drivers.ur.emulate.served` — the server as the emulated rig serves it.
"""
