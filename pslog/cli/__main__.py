import sys

from pslog.cli import main

sys.exit(main())
