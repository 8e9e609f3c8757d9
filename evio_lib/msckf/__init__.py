"""MSCKF back-end (thesis §3.3): filter configuration, state, IMU propagation, state augmentation and updates."""
