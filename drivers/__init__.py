"""Hardware layer of ffexp: device interfaces and back-ends.

This package never imports :mod:`ffexp`; the experiment layer depends on it,
not the other way round.
"""
