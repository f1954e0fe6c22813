"""The private folders that hold a session's uploads, named by the process that made them, so
that the launcher can remove those of a session that died without cleaning up (SIGKILL, the
kernel's out-of-memory killer). Only the standard library: the launcher imports it."""

from __future__ import annotations

import os
import shutil
import stat
import tempfile
from pathlib import Path

PREFIX = "lmapd-upload-"


def new_folder() -> Path:
    """A new private folder (0700) in the temporary directory, named by this process's id."""
    path = Path(tempfile.mkdtemp(prefix=f"{PREFIX}{os.getpid()}-"))
    os.chmod(path, 0o700)
    return path


def remove_folders_of(pid: int, root: Path | None = None) -> int:
    """Remove the upload folders process ``pid`` made (real folders owned by this user, never a
    link); how many were removed."""
    root = Path(tempfile.gettempdir()) if root is None else root
    removed = 0
    for path in root.glob(f"{PREFIX}{int(pid)}-*"):
        try:
            info = path.lstat()
        except OSError:
            continue
        if stat.S_ISDIR(info.st_mode) and info.st_uid == os.getuid():
            shutil.rmtree(path, ignore_errors=True)
            removed += 1
    return removed
