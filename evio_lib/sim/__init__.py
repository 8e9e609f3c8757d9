"""Simulator of a moving camera + IMU in a textured world: scene, trajectories, IMU synthesis, APS frames.

The names a student uses are listed by ``dir(evio_lib.sim)`` and imported on first use; the rest live in the
submodules (``presets``, ``trajectory``, ``scene``, ``imu``, ``rig``, ``aps``, ``tracks``, ``textures``, ``photos``).
"""
from __future__ import annotations

from evio_lib.lazy_exports import lazy_exports

#: name -> submodule of the names this package offers, imported on first use (PEP 562)
_EXPORTS = {
    "PRESETS": "presets", "SimulationConfig": "presets", "simulate_sequence": "presets",
    "simulate_sequence_cached": "presets", "trajectory_from_preset": "trajectory", "scene_from_preset": "scene",
    "ImuNoiseParams": "imu", "ImuData": "imu", "synthesize_imu": "imu", "CameraImuExtrinsics": "rig",
    "ApsParams": "aps", "simulate_feature_tracks": "tracks", "simple_geometry": "tracks", "FeatureFrame": "tracks",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
