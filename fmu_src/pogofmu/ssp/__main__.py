"""``python -m pogofmu.ssp``: the SSP master's command line."""
import sys

from .cli import main

sys.exit(main())
