"""``python -m wheelloader.cli``: the same as the ``wheelloader`` command."""

import sys

from wheelloader.cli import main

sys.exit(main())
