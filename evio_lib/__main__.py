"""Entry point of ``python -m evio_lib``."""
import signal
import sys


def _terminated_while_starting(signum, frame):  # replaced by evio_lib.cli.main's own handler once it runs
    print("error: terminated", file=sys.stderr)
    sys.exit(143)


if __name__ == "__main__":
    signal.signal(signal.SIGTERM, _terminated_while_starting)
    try:
        from evio_lib.cli import main
    except KeyboardInterrupt:  # Ctrl-C while the command is still starting: one line, no traceback
        print("error: interrupted", file=sys.stderr)
        sys.exit(130)
    sys.exit(main())
