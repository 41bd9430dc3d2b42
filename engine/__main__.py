"""``python -m engine``: see :mod:`engine.cli.main`."""

import sys

from .cli.main import main

sys.exit(main())
