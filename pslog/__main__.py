"""``python -m pslog``: the ``pslog`` command (as lazy as ``pslog --help``)."""

import sys

from pslog.cli import main

sys.exit(main())
