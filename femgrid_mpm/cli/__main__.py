"""``python -m femgrid_mpm.cli``: the ``femgrid-mpm`` command line."""

import sys

from . import main

sys.exit(main())
