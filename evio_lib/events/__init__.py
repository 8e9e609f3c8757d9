"""Events: the event array layout, ESIM-style simulation, representations, and reconstruction into image frames.

One call makes any reconstructor: ``evio_lib.events.create_reconstructor(name, width, height, **options)``
(``direct``, ``high_pass``, the shipped ``firenet``, or ``learned`` with ``checkpoint=PATH``).
"""
from evio_lib.events.reconstruct import available_reconstructors, create_reconstructor

__all__ = ["available_reconstructors", "create_reconstructor"]
