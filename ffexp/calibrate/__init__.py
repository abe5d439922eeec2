"""The simulator calibrated to a rig's recordings (``ffexp calibrate``, ``ffexp resimulate``).

- :mod:`ffexp.calibrate.inputs`: what a recording gives a replay, checked;
- :mod:`ffexp.calibrate.resim`: one replay into the sim rig (through ``drivers.factory``);
- :mod:`ffexp.calibrate.pool`: replays in parallel;
- :mod:`ffexp.calibrate.residuals`: recorded against simulated (pure);
- :mod:`ffexp.calibrate.params`: the fittable scene keys and their stages;
- :mod:`ffexp.calibrate.fit`: the staged fit, intervals, identifiability;
- :mod:`ffexp.calibrate.run`: the whole calibration as one call;
- :mod:`ffexp.calibrate.report`, :mod:`ffexp.calibrate.scene_out`,
  :mod:`ffexp.calibrate.simfile`: what it writes.

docs/calibrate.md explains the method.
"""
