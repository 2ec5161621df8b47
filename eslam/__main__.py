"""``python -m eslam``: the ``eslam`` command without the console script (e.g. from a
script that runs the CLI as a subprocess with its own interpreter)."""

import sys

from eslam.cli import main

sys.exit(main())
