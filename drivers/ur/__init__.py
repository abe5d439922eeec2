"""Universal Robots e-Series over RTDE: the protocol (:mod:`drivers.ur.rtde`).

Imports only :mod:`drivers.base`, :mod:`drivers.errors` and :mod:`drivers.config`,
never another back-end. The register map and the rest: docs/ur.md.
"""
