"""KUKA FRI 1.x (KRC2 LR) back-end.

:mod:`~drivers.fri.types` (packet contents in our conventions),
:mod:`~drivers.fri.codec` (packets on the wire), :mod:`~drivers.fri.convert`
(packets <-> :mod:`~drivers.fri.types`, the strategy request and lockstep
marker), :mod:`~drivers.fri.command` (the one neutral command -> FRI command
rule), :mod:`~drivers.fri.driver` (the remote side over UDP: :class:`FriRobot`,
:class:`FriEstimateSensor`), :mod:`~drivers.fri.topics` (the recording topics of
its extras) and :mod:`~drivers.fri.backend` (the rig's ``fri1`` robot and
``fri-estimate`` sensor: config models, ``open``, the registry entry).
Addresses and sockets come from :mod:`drivers.net`.
"""
