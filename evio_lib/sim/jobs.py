"""How many worker processes the simulator uses to render APS frames, and independent runs spread over them.

``EVIO_JOBS`` (a whole number >= 1) when set, else one per core, at most 4 (``joblib.cpu_count`` respects CPU
affinity and container limits). The test runner sets ``EVIO_JOBS=1``: its own workers already use every core. The
frames never depend on the number of processes (``sim.presets.simulate_sequence``).
"""
from __future__ import annotations

import os
from numbers import Integral
from typing import Any, Callable, Sequence

__all__ = ["JOBS_ENV", "check_jobs", "default_jobs", "map_in_workers"]

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


def map_in_workers(function: Callable[..., Any], calls: Sequence[dict[str, Any]], jobs: int | None = None) -> list:
    """Return ``[function(**kwargs) for kwargs in calls]``, the calls spread over ``jobs`` worker processes (joblib).

    ``jobs``: None for :func:`default_jobs`; never more than one per call; 1 runs them here, in order, with no
    worker. For independent, deterministic runs (Monte Carlo seeds, pipeline configurations), whose results are
    then the same in any number of processes.

    >>> map_in_workers(round, [dict(number=2.675, ndigits=1), dict(number=7.5, ndigits=0)], jobs=1)
    [2.7, 8.0]
    """
    calls = list(calls)
    jobs = min(check_jobs(default_jobs() if jobs is None else jobs), max(len(calls), 1))
    if jobs == 1:
        return [function(**kwargs) for kwargs in calls]
    from joblib import Parallel, delayed

    return Parallel(n_jobs=jobs)(delayed(function)(**kwargs) for kwargs in calls)
