"""Former name of :mod:`evio_lib.features.network`, kept for existing imports: the same package object."""
import importlib
import sys

sys.modules[__name__] = importlib.import_module("evio_lib.features.network")
