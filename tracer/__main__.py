"""``python -m tracer`` runs the same entry point as the ``tracer`` console script."""

import sys

from .cli import main

sys.exit(main())
