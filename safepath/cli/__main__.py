"""``python -m safepath.cli``: the ``safepath`` command."""

import sys

from ._main import main

sys.exit(main())
