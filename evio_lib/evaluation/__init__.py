"""Evaluation: trajectory metrics and figures that the course notebooks use.

The names a student uses are listed by ``dir(evio_lib.evaluation)`` and imported on first use (the figure modules
import matplotlib); the rest live in the submodules (``trajectory_metrics``, ``plots_*``).
"""
from __future__ import annotations

from evio_lib.lazy_exports import lazy_exports

#: name -> submodule of the names this package offers, imported on first use (PEP 562)
_EXPORTS = {
    "format_table": "trajectory_metrics", "rmse": "trajectory_metrics", "position_errors": "trajectory_metrics",
    "Alignment": "trajectory_metrics", "RelativePoseErrors": "trajectory_metrics",
    "align_umeyama": "trajectory_metrics", "absolute_trajectory_error": "trajectory_metrics",
    "percent_of_distance": "trajectory_metrics", "plot_image_grid": "plots_events",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
