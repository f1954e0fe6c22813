"""Every third-party import is a declared dependency (issue 29), and the app refuses, with one
message, a trame-server or wslink outside the range its patches were checked against.

The imports are read from the source (``ast``: every ``import``, those inside functions too) and
mapped to their distributions through the installed metadata; ``simcore/`` may import only the core
dependencies, ``app/`` the core and the ``app`` extra, ``tests/`` those and the ``test`` extra,
``validation/`` (``make validate``) the core and the ``validate`` extra, which ``make test`` does
not install: an import of it that no installed distribution provides counts as declared when a
distribution of the extra has its name.
"""

from __future__ import annotations

import ast
import re
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest

import app.server.versions
import simcore.cli
from app.server.versions import (
    CHECKED_RANGES,
    FrameworkVersionError,
    check_framework_versions,
    in_range,
)

ROOT = Path(__file__).resolve().parent.parent
PROJECT = tomllib.loads((ROOT / "pyproject.toml").read_text(encoding="utf-8"))["project"]
LOCAL = {"simcore", "app", "support", "conftest", "setup", "validation"}


def normalized(name: str) -> str:
    """A distribution name as the index compares them (PEP 503)."""
    return re.sub(r"[-_.]+", "-", name).lower()


def requirement_name(requirement: str) -> tuple[str, list[str]]:
    """``"dask[distributed]>=2024.1"`` -> ``("dask", ["distributed"])``."""
    found = re.match(r"\s*([A-Za-z0-9][A-Za-z0-9._-]*)\s*(?:\[([^\]]*)\])?", requirement)
    assert found, requirement
    extras = [e.strip() for e in (found.group(2) or "").split(",") if e.strip()]
    return normalized(found.group(1)), extras


def extra_requirements(distribution: str, extra: str) -> set[str]:
    """The distributions that ``distribution[extra]`` adds (from its installed metadata)."""
    names = set()
    for line in metadata.requires(distribution) or []:
        requirement, _, marker = line.partition(";")
        if re.search(rf"extra\s*==\s*['\"]{re.escape(extra)}['\"]", marker):
            names.add(requirement_name(requirement)[0])
    return names


def declared(*groups: str) -> set[str]:
    """The distributions declared by ``groups`` ("core" or an extra's name), extras followed."""
    names = set()
    for group in groups:
        extra = group != "core"
        for line in PROJECT["optional-dependencies"][group] if extra else PROJECT["dependencies"]:
            name, extras = requirement_name(line)
            names.add(name)
            for extra in extras:
                names |= extra_requirements(name, extra)
    return names


def third_party_imports(folder: str) -> dict[str, str]:
    """Top-level module imported under ``folder`` -> one file that imports it (neither the standard
    library nor the project's own)."""
    found: dict[str, str] = {}
    paths = sorted((ROOT / folder).rglob("*.py"))
    local = LOCAL | {p.stem for p in paths}  # tests import their neighbours by name
    for path in paths:
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.level == 0 and node.module:
                names = [node.module]
            else:
                continue
            for name in names:
                top = name.split(".")[0]
                if top not in sys.stdlib_module_names and top not in local:
                    found.setdefault(top, str(path.relative_to(ROOT)))
    return found


def module_providers() -> dict[str, list[str]]:
    """Top-level module -> the distributions that provide it: ``packages_distributions`` plus the
    single-file extension modules it misses on Python 3.11 (``small_gicp.cpython-311-....so`` at
    the top of a wheel without top_level.txt reads there as a module named up to ``.so``)."""
    providers = {k: list(v) for k, v in metadata.packages_distributions().items()}
    for dist in metadata.distributions():
        for f in dist.files or ():
            if len(f.parts) == 1 and f.name.endswith((".so", ".pyd")):
                providers.setdefault(f.name.split(".")[0], []).append(dist.metadata["Name"])
    return providers


def undeclared(folder: str, *groups: str, by_name: tuple[str, ...] = ()) -> list[str]:
    """The imports of ``folder`` that no distribution declared by ``groups`` provides; an import
    that nothing installed provides is taken by its name among the distributions of the groups
    ``by_name`` (extras that the test environment does not install)."""
    providers = module_providers()
    allowed = declared(*groups)
    named = declared(*by_name) if by_name else set()
    missing = []
    for module, where in sorted(third_party_imports(folder).items()):
        dists = {normalized(d) for d in providers.get(module, [])}
        if not dists and normalized(module) in named:
            continue
        if not dists & allowed:
            missing.append(f"{module} ({where}; from {sorted(dists) or 'nothing installed'})")
    return missing


def test_the_physics_library_imports_only_core_dependencies():
    assert undeclared("simcore", "core") == []


def test_the_app_imports_only_core_and_app_dependencies():
    assert undeclared("app", "core", "app") == []


def test_the_tests_import_only_declared_dependencies():
    assert undeclared("tests", "core", "app", "test") == []


def test_the_validation_imports_only_core_and_validate_dependencies():
    assert undeclared("validation", "core", "validate", by_name=("validate",)) == []


def test_the_validate_extra_is_what_the_validation_imports():
    """Each distribution of the ``validate`` extra is imported by validation/ (by its name) and
    by nothing that ``make test`` runs (simcore, app, tests)."""
    extra = declared("validate")
    imported = {normalized(m) for m in third_party_imports("validation")}
    assert extra <= imported
    for folder in ("simcore", "app", "tests"):
        assert {normalized(m) for m in third_party_imports(folder)} & extra == set(), folder


def test_an_uninstalled_import_counts_only_by_the_name_of_a_named_extra():
    # validation/ imports mitsuba; without the by-name rule it is undeclared where mitsuba is
    # not installed, and with it a name outside the extra still is
    imports = third_party_imports("validation")
    assert "mitsuba" in imports and "mitransient" in imports
    assert normalized("mitsuba") in declared("validate")
    assert normalized("mitsuba") not in declared("core", "app", "test")


def test_the_import_reader_sees_imports_inside_functions():
    # a function-level import (point_to_mesh_m-style lazy imports) counts like a top-level one
    imports = third_party_imports("simcore")
    assert "numba" in imports  # imported inside a try in simcore/echo/kernel.py
    assert "msgpack" in third_party_imports("app")


def test_every_declared_dependency_has_a_lower_bound():
    lines = PROJECT["dependencies"] + [
        line for group in PROJECT["optional-dependencies"].values() for line in group
    ]
    assert [line for line in lines if not re.search(r">=|==|~=", line)] == []


@pytest.mark.parametrize("name", sorted(CHECKED_RANGES))
def test_patched_frameworks_are_declared_with_the_checked_range(name):
    low, high = CHECKED_RANGES[name]
    (line,) = [x for x in PROJECT["optional-dependencies"]["app"] if requirement_name(x)[0] == name]
    specifiers = {s.strip() for s in line.split(";")[0][len(name) :].split(",")}
    assert specifiers == {f">={low}", f"<{high}"}


def test_the_patches_name_releases_within_the_checked_ranges():
    """Each release of a patched framework that app/server/ names (``trame-server 4.1.0``,
    ``wslink 2.6``: what a patch was read against) lies in its checked range, so that a range
    moved in app/server/versions.py without reading the patches again shows here."""
    named = []
    for path in sorted((ROOT / "app" / "server").glob("*.py")):
        text = path.read_text(encoding="utf-8")
        for name, version in re.findall(r"\b(trame-server|wslink) (\d+\.\d+(?:\.\d+)?)\b", text):
            named.append((path.name, name, version))
    assert {n for _, n, _ in named} == set(CHECKED_RANGES)  # each patched framework is named
    outside = [(f, n, v) for f, n, v in named if not in_range(v, *CHECKED_RANGES[n])]
    assert outside == []


def test_the_installed_frameworks_are_in_the_checked_range():
    check_framework_versions()


@pytest.mark.parametrize(
    ("name", "version"),
    [("trame-server", "4.2.0"), ("trame-server", "4.0.9"), ("wslink", "2.7.1"), ("wslink", "3.0")],
)
def test_a_framework_outside_its_range_is_refused_by_name(name, version):
    installed = {n: low for n, (low, _) in CHECKED_RANGES.items()} | {name: version}
    with pytest.raises(FrameworkVersionError, match=rf"{name} {re.escape(version)} is installed"):
        check_framework_versions(installed.__getitem__)


def test_a_missing_framework_is_refused_by_name():
    def installed(name):
        raise metadata.PackageNotFoundError(name)

    with pytest.raises(FrameworkVersionError, match="wslink is not installed"):
        check_framework_versions(installed)


def test_lmapd_app_says_which_framework_is_outside_its_range(monkeypatch, capsys):
    real = metadata.version

    def version(name):
        return "2.8.0" if name == "wslink" else real(name)

    monkeypatch.setattr(app.server.versions.metadata, "version", version)
    assert simcore.cli.main(["app", "--port", "1"]) == 2
    err = capsys.readouterr().err
    assert "wslink 2.8.0 is installed" in err
    assert ">=2.6.0,<2.7" in err
