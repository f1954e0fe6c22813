"""The user's on-disk cache of what is slow to derive and never changes for the same input (the
geometry read from a mesh file, a pulse's timing marks): where it lives, and atomic writes.

The folder is ``$LMAPD_CACHE_DIR`` (``off`` disables the cache), else
``$XDG_CACHE_HOME/lmapd-sim``, else ``~/.cache/lmapd-sim``. Entries are named by a hash of all
they depend on, so a stale one is never read; they are written to a temporary file renamed over
the entry, so a reader sees the old entry, the new one or none, never half of one.
"""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable
from pathlib import Path
from typing import IO

CACHE_ENV = "LMAPD_CACHE_DIR"


def cache_dir() -> Path | None:
    """The folder of the on-disk cache, None when ``$LMAPD_CACHE_DIR`` is ``off``."""
    chosen = os.environ.get(CACHE_ENV)
    if chosen is not None:
        return None if chosen.strip().lower() in ("", "off", "0", "none") else Path(chosen)
    base = os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache"
    return Path(base) / "lmapd-sim"


def write_atomically(file: Path, write: Callable[[IO[bytes]], object], max_entries: int) -> None:
    """Create or replace the entry ``file`` with what ``write`` writes to the open file it is
    given, atomically; then keep the ``max_entries`` most recently written entries of its folder
    (those with its suffix).

    Raises
    ------
    OSError
        The folder cannot be made or written (no temporary file is left behind).
    """
    tmp = None
    try:
        file.parent.mkdir(parents=True, exist_ok=True)
        with tempfile.NamedTemporaryFile(dir=file.parent, suffix=".part", delete=False) as fh:
            tmp = Path(fh.name)
            write(fh)
        os.replace(tmp, file)
    except OSError:
        if tmp is not None:
            tmp.unlink(missing_ok=True)
        raise
    entries = sorted(
        file.parent.glob(f"*{file.suffix}"), key=lambda f: f.stat().st_mtime, reverse=True
    )
    for old in entries[max_entries:]:
        old.unlink(missing_ok=True)
