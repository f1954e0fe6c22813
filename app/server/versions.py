"""The framework versions the app's patches were checked against, and the check made at start.

``app.server.security`` (its ``guard``, ``budget`` and ``door``) and ``app.server.sync`` hook into
private parts of trame-server and wslink (the protocol instance's state push, wslink's chunk header
and handler methods). Those change without notice between releases, so the app runs only with the
releases it was checked against: pyproject.toml declares the same ranges, and
:func:`check_framework_versions` refuses, with one message naming the package, its version and the
range, before any of the app is imported. Standard library only.
"""

from __future__ import annotations

import re
from importlib import metadata

# distribution -> (lowest checked, first release not checked): the ranges of pyproject.toml
CHECKED_RANGES = {
    "trame-server": ("4.1.0", "4.2"),
    "wslink": ("2.6.0", "2.7"),
}
INSTALL_HINT = "pip install 'lmapd-sim[app]' (in a checkout: pip install -e '.[app]')"


class FrameworkVersionError(RuntimeError):
    """A framework the app patches is missing or outside the range it was checked against."""


def release(version: str) -> tuple[int, ...]:
    """The numeric release of a version string: ``"4.1.0"`` -> ``(4, 1, 0)``, ``"2.7rc1"`` ->
    ``(2, 7)`` (a pre-release of 2.7 counts as 2.7: outside a range that ends before 2.7)."""
    head = re.match(r"\d+(?:\.\d+)*", version.strip().lstrip("vV"))
    if head is None:
        raise ValueError(f"not a version: {version!r}")
    return tuple(int(part) for part in head.group().split("."))


def in_range(version: str, low: str, high: str) -> bool:
    """Whether ``low <= version < high`` (releases compared numerically, padded with zeros)."""
    width = 4
    v, lo, hi = (release(x) + (0,) * (width - len(release(x))) for x in (version, low, high))
    return lo <= v < hi


def check_framework_versions(installed=None) -> None:
    """Raise FrameworkVersionError naming each framework outside its checked range.

    ``installed``: distribution name -> version (default: the installed metadata).
    """
    installed = installed or metadata.version
    problems = []
    for name, (low, high) in CHECKED_RANGES.items():
        try:
            version = installed(name)
        except metadata.PackageNotFoundError:
            problems.append(f"{name} is not installed (the app needs {name} >={low},<{high})")
            continue
        if not in_range(version, low, high):
            problems.append(
                f"{name} {version} is installed, but the app was checked against "
                f">={low},<{high} (it patches private parts of {name})"
            )
    if problems:
        raise FrameworkVersionError(
            "; ".join(problems) + f". Install the checked versions: {INSTALL_HINT}"
        )
