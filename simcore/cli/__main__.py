"""``python -m simcore.cli ...``: the ``lmapd`` command."""

from . import run

run()
