"""Simulated image blocks with known truth: the test bed of the bundle adjustment and of the
residual-grid study.

* :func:`uav_block` - a UAV block of strips over a terrain, with GCPs, check points, GNSS/IMU,
  noise, blunders, Brown distortion and image-variant local distortion fields;
* :data:`PRESETS` - the three cameras of the UAV residual study (``"ILCE-7RM2"``,
  ``"FC6310"``, ``"FC300S"``);
* :class:`LocalDistortionField`, :class:`WaveTerrain` - the smooth random surfaces used.

See ``docs/simulation.md``.
"""

from .fields import LocalDistortionField, WaveTerrain
from .presets import PRESETS, CameraPreset, preset
from .uav import SimulatedBlock, uav_block

__all__ = [
    "PRESETS",
    "CameraPreset",
    "LocalDistortionField",
    "SimulatedBlock",
    "WaveTerrain",
    "preset",
    "uav_block",
]
