"""The Franka family's emulated side: the FR3's controller on the simulated world.

- :mod:`~drivers.franka.emulate.controller` — the FR3's torque interface on the world (its
  law: the commanded joint torques on top of its own gravity compensation, its reflexes),
  reporting libfranka's ``RobotState``;
- :mod:`~drivers.franka.emulate.server` — that controller over libfranka's protocol
  (``ffexp emulate --robot fr3``), lockstep or real time, with faults;
- :mod:`~drivers.franka.emulate.lockstep` — the ``franka-sim`` robot: ffexp's Franka
  driver on the same controller in-process;
- :mod:`~drivers.franka.emulate.served` — the server as the emulated rig serves it.
"""
