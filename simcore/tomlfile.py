"""Reading a small TOML file (a scene, a material map, a sweep) safely: a size limit, a clear error
for a folder, a device, an unreadable or too deeply nested file, and messages that quote at most
``MAX_QUOTE_CHARS`` characters of a path or value."""

from __future__ import annotations

import os
import stat
import tomllib
from pathlib import Path
from typing import Any

MAX_TOML_BYTES = 4 * 1024 * 1024  # [B] scene, material map and sweep files are read up to 4 MiB
MAX_QUOTE_CHARS = 200  # [-] characters of a path or bad value a message quotes at most


def clip(text: object, limit: int = MAX_QUOTE_CHARS) -> str:
    """``text`` as a string of at most about ``limit`` characters (the middle cut, the length
    said), for quoting user input in a one-line message."""
    s = str(text)
    if len(s) <= limit:
        return s
    head = limit * 3 // 4
    return f"{s[:head]}...{s[-(limit - head) :]} ({len(s)} characters)"


def read_toml_file(path: str | Path, what: str, error: type[Exception]) -> dict[str, Any]:
    """The tables of the TOML file ``path``; ``error`` naming ``what`` and the file otherwise.

    Parameters
    ----------
    path : str or Path
        The file: a regular file of at most ``MAX_TOML_BYTES``, UTF-8, nested less deeply than
        Python's recursion limit.
    what : str
        What the file is, for the message ("scene file", "material map").
    error : type of Exception
        Raised with one line naming the file (quoted with ``clip``) and what is wrong.
    """
    name = clip(os.fspath(path))
    try:
        info = os.stat(path)
        if stat.S_ISDIR(info.st_mode):
            raise error(f"{what} {name} is a folder, not a file")
        with open(path, "rb") as fh:
            data = fh.read(MAX_TOML_BYTES + 1)
    except FileNotFoundError:
        raise error(f"{what} not found: {name}") from None
    except OSError as exc:
        raise error(f"{what} {name}: cannot read it ({exc.strerror})") from None
    if len(data) > MAX_TOML_BYTES:
        raise error(
            f"{what} {name} is larger than {MAX_TOML_BYTES // 2**20} MiB "
            "(the limit for scene and material files): not a scene file"
        )
    try:
        return tomllib.loads(data.decode("utf-8"))
    except UnicodeDecodeError as exc:
        raise error(f"{what} {name}: not UTF-8 text ({exc.reason} at byte {exc.start})") from None
    except ValueError as exc:  # TOMLDecodeError, or an integer of more than 4300 digits
        raise error(f"{what} {name}: not valid TOML: {clip(exc)}") from None
    except RecursionError:
        raise error(f"{what} {name}: tables or arrays nested too deeply") from None
