"""ATI Net F/T back-end: RDT codec (:mod:`drivers.netft.codec`).

The UDP client and the sensor emulator build on the codec.
"""
