"""MSCKF back-end (thesis §3.3): filter configuration, state, IMU propagation, state augmentation and updates.

    from evio_lib.msckf import Msckf, MsckfConfig, initial_state_from_truth
    config = MsckfConfig()
    msckf = Msckf(config, initial_state_from_truth(t0, R_ItoG, p_IinG, v_IinG, R_CtoI, p_CinI, config))
    msckf.feed_imu(imu_t, gyro, accel)
    out = msckf.process_image(t, ids, xy)            # each image's tracks; out.p_IinG, out.P_imu, ...

The names a student uses are listed by ``dir(evio_lib.msckf)`` and imported on first use (so that importing the
package stays cheap); the rest live in the submodules: ``config`` (every parameter), ``state`` (the error state and
its covariance), ``propagation``, ``augmentation``, ``triangulation``, ``update`` (the update's pure functions),
``observability`` (the OC-EKF), ``initialization``, ``zero_velocity``, the filter's parts ``imu_buffer``,
``feature_database`` and ``updater``, ``filter`` (``Msckf``, which composes them), ``error_state_attitude`` (the
Kalman-filter lesson's small filter) and ``experiment`` (the MSCKF on simulated tracks, ``vio-sim``).
"""
from __future__ import annotations

from evio_lib.lazy_exports import lazy_exports

#: name -> submodule of the names this package offers, imported on first use (PEP 562)
_EXPORTS = {
    # the filter and its parts
    "Msckf": "filter", "FilterOutput": "filter", "MsckfWarning": "filter", "MsckfConfig": "config",
    "ImuBuffer": "imu_buffer", "StepRefusedError": "imu_buffer", "FeatureDatabase": "feature_database",
    "FeatureUse": "feature_database", "whitening_matrices": "feature_database", "MsckfUpdater": "updater",
    "UpdateResult": "updater", "apply_correction": "updater",
    # the state and how it starts
    "FilterState": "state", "ImuState": "state", "CameraState": "state", "inject_error": "state",
    "state_difference": "state", "remove_camera_states": "state", "initial_state_from_truth": "initialization",
    "initial_state_from_static": "initialization", "static_initialization": "initialization",
    # the steps as functions (the lessons' building blocks)
    "propagate": "propagation", "integrate_imu": "propagation", "ImuGapError": "propagation",
    "augment_state": "augmentation", "augmentation_jacobian": "augmentation",
    "triangulate_inverse_depth": "triangulation", "triangulate_inverse_depth_batch": "triangulation",
    "feature_jacobians": "update", "nullspace_project": "update", "measurement_compress": "update",
    "kalman_update": "update", "chi_square_gate": "update", "chi_square_threshold": "update",
    "gating_mean_shrink": "update", "state_nullspace": "observability", "camera_nullspace": "observability",
    "imu_nullspace": "observability", "constrain_transition": "observability",
    "constrain_projected_jacobian": "observability", "constrain_feature_jacobians": "observability",
    "ZeroVelocityConfig": "zero_velocity", "StandstillDetector": "zero_velocity",
    # the MSCKF on simulated tracks (vio-sim)
    "VioSimConfig": "experiment", "VioSimResult": "experiment", "run_vio_sim": "experiment",
    "run_vio_sim_config": "experiment", "run_vio_sim_seeds": "experiment", "simulate_data": "experiment",
    "simulated_data_from_recording": "experiment",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
