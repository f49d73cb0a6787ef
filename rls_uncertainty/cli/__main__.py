"""``python -m rls_uncertainty.cli``: the ``rls-uncertainty`` command."""

import sys

from . import main

sys.exit(main())
