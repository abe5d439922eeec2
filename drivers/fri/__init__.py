"""KUKA FRI 1.x (KRC2 LR) back-end.

:mod:`~drivers.fri.codec` (packets), :mod:`~drivers.fri.convert` (packets <->
``drivers.base`` objects, the strategy request and lockstep marker),
:mod:`~drivers.fri.driver` (the remote side over UDP: :class:`FriRobot`,
:class:`FriEstimateSensor`), :mod:`~drivers.fri.emulator` (the controller side
over a SimWorld: ``ffexp emulate``), :mod:`~drivers.fri.udp` (addresses, sockets).
"""
