"""Simulator of a moving camera + IMU in a textured world: scene, trajectories, IMU synthesis, APS frames."""
