"""``python -m kubric ...`` = the ``kubric`` command."""

import sys

from kubric.cli import main

sys.exit(main())
