"""Allow ``python -m swingrt``."""

import sys

from swingrt.cli import main

sys.exit(main())
