"""``python -m companion``: the ``companion`` command line."""

import sys

from .cli import main

sys.exit(main())
