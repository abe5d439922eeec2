"""ATI Net F/T back-end.

:mod:`~drivers.netft.codec` (RDT packets, scaling, status bits),
:mod:`~drivers.netft.client` (the sensor over UDP: :class:`NetFtClient`).
The emulated box fed by the simulator is :mod:`drivers.emulate.netft_box`
(this package imports no other back-end).
"""
