"""Events: the event array layout, ESIM-style simulation, representations, and reconstruction into image frames.

One call makes any reconstructor: ``evio_lib.events.create_reconstructor(name, width, height, **options)``
(``direct``, ``high_pass``, the shipped ``firenet``, or ``learned`` with ``checkpoint=PATH``).
"""
from evio_lib.lazy_exports import lazy_exports

__all__ = ["available_reconstructors", "create_reconstructor"]
# imported on first use: the command-line options modules of this package must not pull in torch
__getattr__, __dir__ = lazy_exports(__name__, {name: "reconstruct" for name in __all__}, globals())
