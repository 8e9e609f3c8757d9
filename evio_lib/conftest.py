"""pytest set-up for the doctests of evio_lib (collected by ``python tools/run_tests.py``; not part of the API)."""
import sys

import pytest


@pytest.fixture(autouse=True)
def _close_figures():
    """Close the figures a doctest opened (plotting examples), so that they do not pile up over the session."""
    yield
    pyplot = sys.modules.get("matplotlib.pyplot")
    if pyplot is not None:
        pyplot.close("all")
