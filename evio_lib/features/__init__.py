"""Features: one interface (``create_detector(name).detect_and_describe(image)``) for classical and learned detectors."""
