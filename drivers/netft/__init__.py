"""ATI Net F/T back-end.

:mod:`~drivers.netft.codec` (RDT packets, scaling, status bits),
:mod:`~drivers.netft.client` (the sensor over UDP: :class:`NetFtClient`),
:mod:`~drivers.netft.emulator` (an emulated box fed by the simulator).
"""
