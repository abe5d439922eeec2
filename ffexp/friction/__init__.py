"""Residual friction of the air-bed target from video.

- :mod:`ffexp.friction.fit`: the maths (sliding window, quadratic fit, bound);
- :mod:`ffexp.friction.track`: finding and tracking the target (entry point), built on
  :mod:`ffexp.friction.video` (decoding), :mod:`ffexp.friction.markerless` and
  :mod:`ffexp.friction.marker` (the two trackers), :mod:`ffexp.friction.homography`
  (pixels to metres);
- :mod:`ffexp.friction.synth`: synthetic videos with a known deceleration;
- :mod:`ffexp.friction.estimate`: video to ``mu``;
- :mod:`ffexp.friction.plot`, :mod:`ffexp.friction.record`: outputs.
"""

from __future__ import annotations

from ffexp.friction.estimate import FrictionResult, Scale, estimate_video
from ffexp.friction.fit import FrictionEstimate, estimate_friction, fit_quadratic
from ffexp.friction.synth import SynthConfig, SynthTruth, write_video

__all__ = [
    "FrictionEstimate",
    "FrictionResult",
    "Scale",
    "SynthConfig",
    "SynthTruth",
    "estimate_friction",
    "estimate_video",
    "fit_quadratic",
    "write_video",
]
