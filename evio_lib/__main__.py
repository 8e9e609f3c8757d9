"""Entry point of ``python -m evio_lib``.

An interrupted command (Ctrl-C: 130, SIGTERM: 143) has already cleaned up (an output folder being written removed its
temporary folder) and printed its one line when ``main`` returns. The process then ends with ``os._exit`` instead of
the interpreter's shutdown: native threads (OpenMP, torch, numba, matplotlib's) that the interruption left mid-call
could otherwise touch Python state while the interpreter finalises ("Fatal Python error: PyThreadState_Get", exit
134, seen once in 24 interrupts of ``run --out`` while it wrote figures).
"""
import os
import signal
import sys

_INTERRUPTED = (130, 143)


def _terminated_while_starting(signum, frame):  # replaced by evio_lib.cli.main's own handler once it runs
    print("error: terminated", file=sys.stderr)
    sys.exit(143)


def _exit(code: int) -> None:
    """End the process with ``code``: at once (flushed, no interpreter shutdown) after an interruption."""
    if code in _INTERRUPTED:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)
    sys.exit(code)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, _terminated_while_starting)
    try:
        from evio_lib.cli import main
    except KeyboardInterrupt:  # Ctrl-C while the command is still starting: one line, no traceback
        print("error: interrupted", file=sys.stderr)
        _exit(130)
    _exit(main())
