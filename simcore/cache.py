"""The user's on-disk cache of what is slow to derive and never changes for the same input (the
geometry read from a mesh file, a pulse's timing marks, the Geiger-mode tables): where it lives,
atomic writes, and :class:`TableCache`, the tables that depend on a few scalars.

The folder is ``$LMAPD_CACHE_DIR`` (``off`` disables the cache), else
``$XDG_CACHE_HOME/lmapd-sim``, else ``~/.cache/lmapd-sim``. Entries are named by a hash of all
they depend on, so a stale one is never read; they are written to a temporary file renamed over
the entry, so a reader sees the old entry, the new one or none, never half of one.
"""

from __future__ import annotations

import hashlib
import io
import os
import tempfile
import threading
import warnings
from collections import OrderedDict
from collections.abc import Callable
from pathlib import Path
from typing import IO, Any

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


class TableCache:
    """Tables (named numpy arrays) that depend on a few scalars only, each computed once per
    argument set: kept in memory (the ``max_memory`` most recently used) and on disk under
    ``<cache_dir>/tables/<name>/`` (the ``max_entries`` most recent), each entry named by the
    SHA-256 of its arguments (floats exactly), the bytes of the ``sources`` that compute it and
    numpy's and scipy's versions, so that a table written by another version of the code is
    never read. The entry also holds its own key text, checked on reading. A corrupt entry is
    computed again, an unwritable cache skipped, each with a warning.

    ``computed``, ``memory_hits`` and ``disk_hits`` count what each :meth:`get` did (tests and
    benchmarks read them).
    """

    def __init__(
        self, name: str, sources: tuple[Path, ...], max_memory: int = 8, max_entries: int = 64
    ):
        self.name = name
        self.sources = tuple(sources)
        self.max_memory = max_memory
        self.max_entries = max_entries
        self._memory: OrderedDict[tuple, dict] = OrderedDict()
        self._digest: str | None = None
        self._lock = threading.Lock()
        self.computed = self.memory_hits = self.disk_hits = 0

    def clear_memory(self) -> None:
        """Forget the tables held in memory (those on disk stay)."""
        self._memory.clear()

    def _code_digest(self) -> str:
        """SHA-256 of the sources and the numerical libraries' versions (read once)."""
        if self._digest is None:
            import numpy  # noqa: PLC0415
            import scipy  # noqa: PLC0415

            digest = hashlib.sha256()
            for source in self.sources:
                digest.update(Path(source).read_bytes())
            digest.update(f"numpy {numpy.__version__} scipy {scipy.__version__}".encode())
            self._digest = digest.hexdigest()
        return self._digest

    def key_text(self, args: tuple) -> str:
        """The text an entry's name is the hash of: the code's digest and the arguments."""
        return f"{self.name} {self._code_digest()} " + " ".join(_exact(a) for a in args)

    def entry(self, args: tuple) -> Path | None:
        """The on-disk entry of ``args`` (None without a cache folder)."""
        folder = cache_dir()
        if folder is None:
            return None
        name = hashlib.sha256(self.key_text(args).encode()).hexdigest()
        return folder / "tables" / self.name / f"{name}.npz"

    def get(self, args: tuple, compute: Callable[[], dict]) -> dict:
        """The table of ``args``: from memory, else from disk, else ``compute()`` (a dict of
        arrays), then kept in both. The arrays returned are read-only (shared)."""
        with self._lock:
            held = self._memory.get(args)
            if held is not None:
                self._memory.move_to_end(args)
                self.memory_hits += 1
                return held
        try:
            file = self.entry(args)
            text = self.key_text(args) if file is not None else ""
        except OSError:  # the sources are not readable: no disk cache
            file, text = None, ""
        table = _read_table(file, text) if file is not None else None
        if table is not None:
            self.disk_hits += 1
        else:
            table = compute()
            self.computed += 1
            if file is not None:
                _write_table(file, text, table, self.max_entries)
        for value in table.values():
            value.setflags(write=False)
        with self._lock:  # sessions of the app run frames on threads of their own
            self._memory[args] = table
            while len(self._memory) > self.max_memory:
                self._memory.popitem(last=False)
        return table


def _exact(value) -> str:
    """An argument as text: floats exactly (their hex form), anything else by its repr."""
    if isinstance(value, float):
        return value.hex()
    return repr(value)


_KEY = "__key__"


def _read_table(file: Path, text: str) -> dict | None:
    """The arrays stored in ``file`` if it holds the key ``text``; None if none (or corrupt,
    with a warning)."""
    import numpy as np  # noqa: PLC0415

    try:
        with np.load(file) as data:
            if str(data[_KEY]) != text:
                raise ValueError("its key is another table's")
            return {name: data[name] for name in data.files if name != _KEY}
    except (FileNotFoundError, NotADirectoryError):
        return None
    except (OSError, ValueError, KeyError, TypeError, EOFError) as exc:
        warnings.warn(f"table cache {file} is corrupt ({exc}); computed again", stacklevel=3)
        return None


def _write_table(file: Path, text: str, table: dict, max_entries: int) -> None:
    import numpy as np  # noqa: PLC0415

    buffer = io.BytesIO()
    arrays: dict[str, Any] = {_KEY: np.array(text), **table}
    np.savez(buffer, **arrays)
    try:
        write_atomically(file, lambda fh: fh.write(buffer.getvalue()), max_entries)
    except OSError as exc:
        warnings.warn(f"table cache {file.parent} is not writable ({exc})", stacklevel=3)
