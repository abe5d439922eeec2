"""KUKA FRI 1.x (KRC2 LR) back-end: packet codec (:mod:`drivers.fri.codec`).

The remote-side UDP driver and the controller-side emulator build on the codec.
"""
