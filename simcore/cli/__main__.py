"""``python -m simcore.cli ...``: the ``lmapd`` command."""

import sys

from . import main

sys.exit(main())
