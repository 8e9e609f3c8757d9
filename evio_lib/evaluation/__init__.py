"""Evaluation: trajectory metrics and figures that the course notebooks use."""
