"""evio_lib.threads: BLAS thread limits set after NumPy is loaded, checked with threadpoolctl's own report."""
import os

import numpy as np
import pytest
from threadpoolctl import threadpool_info

from evio_lib.threads import set_threads, single_threaded_blas


def _blas_threads() -> list[int]:
    return [lib["num_threads"] for lib in threadpool_info() if lib["user_api"] == "blas"]


def test_single_threaded_blas_limits_every_loaded_blas_and_restores_the_counts():
    import scipy.linalg  # noqa: F401 - SciPy's own OpenBLAS is limited too

    before = _blas_threads()
    assert len(before) >= 1
    with single_threaded_blas():
        assert _blas_threads() == [1] * len(before)
        assert np.allclose(np.linalg.inv(np.diag([2.0, 4.0])), np.diag([0.5, 0.25]))
    assert _blas_threads() == before


def test_set_threads_limits_torch_opencv_and_blas_then_restore(monkeypatch):
    import cv2
    import torch

    from evio_lib.threads import THREAD_ENV_NAMES, _blas_controller

    for name in THREAD_ENV_NAMES:  # set_threads writes them: monkeypatch puts the old values back after the test
        monkeypatch.setenv(name, os.environ.get(name, "1"))
    controller = _blas_controller()
    saved_blas = [(lib, lib.num_threads) for lib in controller.lib_controllers]
    saved = (torch.get_num_threads(), cv2.getNumThreads())
    try:
        set_threads(np.int64(1))
        assert torch.get_num_threads() == 1 and cv2.getNumThreads() == 1
        assert set(_blas_threads()) == {1}
        assert os.environ["OPENBLAS_NUM_THREADS"] == "1"
    finally:
        torch.set_num_threads(saved[0])
        cv2.setNumThreads(saved[1])
        for lib, n in saved_blas:  # every library the controller changed, BLAS or OpenMP, gets its own count back
            lib.set_num_threads(n)


@pytest.mark.parametrize("bad", [0, -1, 1.5, True, "2", np.float64(2.0)])
def test_set_threads_refuses_what_is_not_a_positive_count(bad):
    with pytest.raises(ValueError, match="threads must be an integer >= 1"):
        set_threads(bad)


def test_the_filter_step_runs_with_one_blas_thread(monkeypatch):
    """Msckf.process_image runs its body under single_threaded_blas (the cause of its 6x CPU cost on 2 cores)."""
    from evio_lib.msckf import filter as filter_module

    seen = []
    monkeypatch.setattr(filter_module.Msckf, "_process_image", lambda self, *a: seen.append(_blas_threads()))
    filter_module.Msckf.process_image(object.__new__(filter_module.Msckf), 0.0, [], np.zeros((0, 2)))
    assert seen and set(seen[0]) == {1}
