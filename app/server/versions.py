"""The framework versions the app's patches were checked against, and the check made at start.

``app.server.security`` (its ``guard``, ``budget`` and ``door``) and ``app.server.sync`` hook into
private parts of trame-server and wslink (the protocol instance's state push, wslink's chunk header
and handler methods). Those change without notice between releases, so the app runs only with the
releases it was checked against: pyproject.toml declares the same ranges, and
:func:`check_framework_versions` refuses, with one message naming the package, its version and the
range, before any of the app is imported. The standard library and ``packaging`` only (no
framework module).
"""

from __future__ import annotations

from importlib import metadata

from packaging.specifiers import SpecifierSet

# distribution -> the releases checked (PEP 440 specifiers): the ranges of pyproject.toml
CHECKED_RANGES = {
    "trame-server": ">=4.1.0,<4.2",
    "wslink": ">=2.6.0,<2.7",
}
INSTALL_HINT = "pip install 'lmapd-sim[app]' (in a checkout: pip install -e '.[app]')"


class FrameworkVersionError(RuntimeError):
    """A framework the app patches is missing or outside the range it was checked against."""


def in_range(version: str, specifiers: str) -> bool:
    """Whether ``version`` satisfies ``specifiers`` (``">=2.6.0,<2.7"``), pre-releases included:
    ``2.6.1rc1`` is in that range, ``2.7rc1`` is not (a pre-release of 2.7 is not below 2.7), and
    a string that is no version is in no range."""
    return SpecifierSet(specifiers).contains(version.strip(), prereleases=True)


def check_framework_versions(installed=None) -> None:
    """Raise FrameworkVersionError naming each framework outside its checked range.

    ``installed``: distribution name -> version (default: the installed metadata).
    """
    installed = installed or metadata.version
    problems = []
    for name, specifiers in CHECKED_RANGES.items():
        try:
            version = installed(name)
        except metadata.PackageNotFoundError:
            problems.append(f"{name} is not installed (the app needs {name} {specifiers})")
            continue
        if not in_range(version, specifiers):
            problems.append(
                f"{name} {version} is installed, but the app was checked against "
                f"{specifiers} (it patches private parts of {name})"
            )
    if problems:
        raise FrameworkVersionError(
            "; ".join(problems) + f". Install the checked versions: {INSTALL_HINT}"
        )
