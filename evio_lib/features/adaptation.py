"""Former name of :mod:`evio_lib.features.training.adaptation`, kept for existing imports: the same module object."""
import importlib
import sys

sys.modules[__name__] = importlib.import_module("evio_lib.features.training.adaptation")
