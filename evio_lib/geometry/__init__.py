"""Geometry: rotations (JPL quaternions), the pinhole-radtan camera, epipolar geometry and homographies.

Import from the submodules, e.g. ``from evio_lib.geometry.rotation import quat_to_rot``.
"""
