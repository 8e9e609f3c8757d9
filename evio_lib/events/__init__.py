"""Events: the event array layout, ESIM-style simulation, representations, and reconstruction into image frames.

The names a student uses are here (``dir(evio_lib.events)``): the event array (``make_events``, ``events_between``,
``event_count_image``: a count frame), the simulator, windows and representations (``polarity_frame``,
``time_surface``, ``voxel_grid``), a motion-compensated frame, and the reconstructors. One call makes any
reconstructor: ``evio_lib.events.create_reconstructor(name, width, height, **options)``
(``direct``, ``high_pass``, the shipped ``firenet``, or ``learned`` with ``checkpoint=PATH``).
"""
from evio_lib.lazy_exports import lazy_exports

#: name -> module of the names this package offers, imported on first use: the command-line options modules of this
#: package must not pull in torch
_EXPORTS = {
    "EVENT_DTYPE": "array", "make_events": "array", "events_between": "array", "event_count_image": "array",
    "simulate_events": "simulate", "EventCameraParams": "simulate",
    "count_windows": "representations", "time_windows": "representations", "polarity_frame": "representations",
    "time_surface": "representations", "voxel_grid": "representations",
    "motion_compensated_frame": "motion_compensation",
    "available_reconstructors": "reconstruct", "create_reconstructor": "reconstruct",
}
__all__ = list(_EXPORTS)
__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
