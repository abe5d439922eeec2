"""RTDE (Real-Time Data Exchange), protocol version 2, written from UR's public RTDE Guide.

:mod:`~drivers.ur.rtde.codec` (packages), :mod:`~drivers.ur.rtde.fields` (field
types, recipes), :mod:`~drivers.ur.rtde.variables` (the variables and their
types), :mod:`~drivers.ur.rtde.client` (:class:`~drivers.ur.rtde.client.RtdeClient`);
its errors are in :mod:`drivers.ur.errors`.
"""
