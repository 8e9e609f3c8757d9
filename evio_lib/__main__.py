"""Entry point of ``python -m evio_lib``."""
import sys

from evio_lib.cli import main

sys.exit(main())
