"""``python -m tools.tlog`` = ``flowgap-tlog``."""

import sys

from tools.tlog.cli import main

sys.exit(main())
