"""Every third-party import is a declared dependency and every dependency is used (issue 29; read by
deptry since issue 44), and the app refuses, with one message, a trame-server or wslink outside the
range its patches were checked against.

deptry reads every ``import`` (those inside functions too) and the declarations of pyproject.toml
(``[tool.deptry]``); :func:`deptry_runs` are the three runs of ``make lint``: the whole project
(scripts/ and tests/ included) imports only declared dependencies, not the docs extra, and leaves
none unused; simcore/
imports only the core ones (every extra counts as a development one there) and uses each of them;
app/ imports the core and the ``app`` extra. What deptry does not say stays here: a lower bound on
every declaration, and the framework fence of app/server/versions.py.
"""

from __future__ import annotations

import re
import subprocess
import sys
import tomllib
from importlib import metadata
from pathlib import Path

import pytest
from packaging.requirements import Requirement
from packaging.specifiers import SpecifierSet

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


def extras_but(*names: str) -> str:
    """The optional extras of pyproject.toml but ``names``, comma-separated (the Makefile's
    ``extras_but``)."""
    return ",".join(e for e in PROJECT["optional-dependencies"] if e not in names)


def deptry_runs() -> dict[str, list[str]]:
    """The deptry runs of ``make lint`` (the Makefile's ``lint``), by what they check.

    The test folders are roots of their own because pytest puts each on ``sys.path`` (a test
    imports its neighbour by name); ``validation/`` is scanned where it exists.
    """
    tests = sorted(
        f"tests/{p.name}/"
        for p in (ROOT / "tests").iterdir()
        if p.is_dir() and p.name != "__pycache__"
    )
    validation = ["validation"] if (ROOT / "validation").is_dir() else []
    return {
        "all declared, none unused": ["simcore", "app", "scripts", *validation, "tests", *tests],
        "simcore: the core only": [
            *("simcore", "--optional-dependencies-dev-groups", extras_but()),
        ],
        "app: the core and the app extra": [
            *("app", "--optional-dependencies-dev-groups", extras_but("app")),
            *("--ignore", "DEP002"),  # the core is the library's; app/ need not use all of it
        ],
        **(
            {  # make validate's check: the core and the validate extra (Mitsuba, mitransient)
                "validation: the core and the validate extra": [
                    *("validation", "--optional-dependencies-dev-groups", extras_but("validate")),
                    *("--ignore", "DEP002"),
                ]
            }
            if validation
            else {}
        ),
    }


def deptry(*args: str, cwd: Path = ROOT) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "deptry", "--no-ansi", "--config", str(ROOT / "pyproject.toml")]
        + list(args),
        capture_output=True,
        text=True,
        cwd=cwd,
    )


@pytest.mark.parametrize("run", sorted(deptry_runs()))
def test_deptry_finds_no_dependency_issue(run):
    done = deptry(*deptry_runs()[run])
    assert done.returncode == 0, done.stdout + done.stderr


def test_deptry_finds_an_app_import_an_undeclared_one_and_an_unused_dependency(tmp_path):
    """The library run, on a library of one module whose function imports trame (the app extra's)
    and requests (declared by nobody here): both found, and every core dependency unused."""
    (tmp_path / "simcore").mkdir()
    (tmp_path / "simcore" / "late.py").write_text(
        "def f():\n    import trame\n    import requests\n"
    )
    args = deptry_runs()["simcore: the core only"]
    done = deptry(*args, cwd=tmp_path)
    said = done.stdout + done.stderr
    assert done.returncode == 1
    assert "simcore/late.py:2:12: DEP004 'trame' imported but declared as a dev dependency" in said
    assert "simcore/late.py:3:12: DEP003 'requests'" in said
    assert "DEP002 'numpy' defined as a dependency but not used" in said


def test_every_declared_dependency_has_a_lower_bound():
    lines = PROJECT["dependencies"] + [
        line for group in PROJECT["optional-dependencies"].values() for line in group
    ]
    assert [line for line in lines if not re.search(r">=|==|~=", line)] == []


@pytest.mark.parametrize("name", sorted(CHECKED_RANGES))
def test_patched_frameworks_are_declared_with_the_checked_range(name):
    (requirement,) = [
        r for r in map(Requirement, PROJECT["optional-dependencies"]["app"]) if r.name == name
    ]
    assert requirement.specifier == SpecifierSet(CHECKED_RANGES[name])


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
    outside = [(f, n, v) for f, n, v in named if not in_range(v, CHECKED_RANGES[n])]
    assert outside == []


@pytest.mark.parametrize(
    ("version", "inside"),
    [
        ("2.6.0", True),
        ("2.6.9", True),
        ("2.6.1rc1", True),  # a pre-release inside the range
        ("2.7rc1", False),  # a pre-release of 2.7 is not below 2.7
        ("2.7.0", False),
        ("2.5.9", False),
        ("not a version", False),
    ],
)
def test_the_fence_reads_versions_as_pep_440_does(version, inside):
    assert in_range(version, ">=2.6.0,<2.7") is inside


def test_the_installed_frameworks_are_in_the_checked_range():
    check_framework_versions()


def inside_version(name: str) -> str:
    """The lowest release of ``name``'s checked range (its ``>=`` bound)."""
    (low,) = [s.version for s in SpecifierSet(CHECKED_RANGES[name]) if s.operator == ">="]
    return low


@pytest.mark.parametrize(
    ("name", "version"),
    [("trame-server", "4.2.0"), ("trame-server", "4.0.9"), ("wslink", "2.7.1"), ("wslink", "3.0")],
)
def test_a_framework_outside_its_range_is_refused_by_name(name, version):
    installed = {n: inside_version(n) for n in CHECKED_RANGES} | {name: version}
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
