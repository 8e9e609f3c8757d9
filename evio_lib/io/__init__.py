"""Readers and writers for real recording layouts (ECD text, EuRoC ASL, AEDAT4, TUM) and the npz cache."""
