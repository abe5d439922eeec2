"""KUKA FRI 1.x (KRC2 LR) back-end.

:mod:`~drivers.fri.types` (packet contents in our conventions),
:mod:`~drivers.fri.codec` (packets on the wire), :mod:`~drivers.fri.convert`
(packets <-> :mod:`~drivers.fri.types`, the strategy request and lockstep
marker), :mod:`~drivers.fri.command` (the one neutral command -> FRI command
rule), :mod:`~drivers.fri.settings` and :mod:`~drivers.fri.driver` (the
remote side over UDP: :class:`FriRobot`, :class:`FriEstimateSensor`).
Addresses and sockets come from :mod:`drivers.net`.
"""
