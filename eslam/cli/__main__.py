"""``python -m eslam.cli``: the ``eslam`` command without the console script."""

from __future__ import annotations

import sys

from eslam.cli import main

sys.exit(main())
