"""``python -m companion``: the same as the ``companion`` console script."""

import sys

from companion.cli import main

sys.exit(main())
