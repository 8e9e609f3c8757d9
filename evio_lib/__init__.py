"""evio_lib: event-based visual-inertial odometry with learned features."""

__version__ = "0.1.0"
