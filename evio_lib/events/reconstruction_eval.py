"""Former name of :mod:`evio_lib.events.reconstruction.evaluation` (kept so existing imports work): the same module object."""
import importlib
import sys

sys.modules[__name__] = importlib.import_module("evio_lib.events.reconstruction.evaluation")
