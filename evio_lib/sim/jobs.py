"""How many worker processes the simulator uses to render APS frames.

``EVIO_JOBS`` (a whole number >= 1) when set, else one per core, at most 4 (``joblib.cpu_count`` respects CPU
affinity and container limits). The test runner sets ``EVIO_JOBS=1``: its own workers already use every core. The
frames never depend on the number of processes (``sim.presets.simulate_sequence``).
"""
from __future__ import annotations

import os
from numbers import Integral

__all__ = ["JOBS_ENV", "check_jobs", "default_jobs"]

JOBS_ENV = "EVIO_JOBS"


def check_jobs(jobs: object) -> int:
    """Return ``jobs`` as an int >= 1, or raise ValueError naming the expected form."""
    if isinstance(jobs, bool) or not isinstance(jobs, Integral) or jobs < 1:
        raise ValueError(f"jobs must be an integer >= 1 (worker processes); got {jobs!r}")
    return int(jobs)


def default_jobs() -> int:
    """Return ``EVIO_JOBS`` when set, else one process per core, at most 4.

    >>> check_jobs(2), check_jobs(default_jobs()) >= 1
    (2, True)
    """
    value = os.environ.get(JOBS_ENV, "").strip()
    if value:
        try:
            return check_jobs(int(value))
        except ValueError:
            raise ValueError(f"{JOBS_ENV} must be a whole number >= 1 (worker processes); got {value!r}") from None
    from joblib import cpu_count

    return min(cpu_count(), 4)
