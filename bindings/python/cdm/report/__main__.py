"""``python3 -m cdm.report``: the command line (see the package's docstring)."""

import sys

from .writer import main

sys.exit(main())
