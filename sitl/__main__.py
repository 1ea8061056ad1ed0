"""``python -m sitl``: the ``sitl`` command line."""

import sys

from .cli import main

sys.exit(main())
