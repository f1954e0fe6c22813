"""The package layout of issue 14: the physics library loads no front-end library, the commands
live in ``simcore/cli/`` and nothing else imports them, and no module imports itself in a circle.

The layers are import-linter's contracts (pyproject.toml, ``[tool.importlinter]``; ``make lint``
runs them too): simcore's floors and the app's, no circle between the modules or packages of one
package, simcore never importing the app, the commands imported by no one, the controller by
``app.main`` alone, the ui taking the logic's package interface only, the payloads no reproduction
code. What the contracts cannot say stays here: what ``import simcore``, ``lmapd --help`` and the
zygote load when run (a function-level import is in the contracts' graph but not loaded), a circle
through a package's own ``__init__`` (no sibling of its modules), the names the ui takes from
``app.logic`` (the contracts see modules, not names), and ``scripts/`` (no package).
"""

from __future__ import annotations

import ast
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import grimp
import pytest

ROOT = Path(__file__).resolve().parent.parent
FRONT_END = ("matplotlib", "dask", "distributed", "pyarrow", "h5py", "laspy", "argparse")
# lint-imports with the project's contracts (argv[1]), those named after it alone
LINT_IMPORTS = (
    "import sys; from importlinter.cli import lint_imports; "
    "sys.exit(lint_imports(sys.argv[1], limit_to_contracts=tuple(sys.argv[2:]), no_cache=True, "
    "no_logo=True))"
)


def lint_imports(*contracts: str, root: Path = ROOT) -> subprocess.CompletedProcess:
    """lint-imports in ``root`` (its packages first on the path); ``contracts`` alone if named."""
    env = {**os.environ, "PYTHONPATH": str(root), "COLUMNS": "200"}
    return subprocess.run(
        [sys.executable, "-c", LINT_IMPORTS, str(ROOT / "pyproject.toml"), *contracts],
        capture_output=True,
        text=True,
        cwd=root,
        env=env,
    )


def test_the_import_contracts_are_kept():
    done = lint_imports()
    assert done.returncode == 0, done.stdout + done.stderr
    assert "0 broken" in done.stdout


def copy_of_the_packages(folder: Path) -> Path:
    """simcore/ and app/ (their Python files) copied into ``folder``."""
    for package in ("simcore", "app"):
        for path in (ROOT / package).rglob("*.py"):
            copy = folder / path.relative_to(ROOT)
            copy.parent.mkdir(parents=True, exist_ok=True)
            shutil.copyfile(path, copy)
    return folder


def test_a_copy_of_the_packages_keeps_the_contracts(tmp_path):
    # the ground of the test below: what breaks there is the one added import
    done = lint_imports(root=copy_of_the_packages(tmp_path))
    assert done.returncode == 0, done.stdout + done.stderr


@pytest.mark.parametrize(
    ("module", "line", "contract"),
    [
        ("simcore/constants.py", "from simcore import pipeline", "simcore-layers"),
        ("simcore/receivers/gm_apd/events.py", "from . import records", "cycles"),
        ("simcore/pipeline.py", "import app.engine", "simcore-no-app"),
        ("simcore/io.py", "import simcore", "simcore-facade"),
        ("app/state.py", "import app.engine", "app-layers"),
        ("app/server/door.py", "from app import main", "app-layers"),
        ("app/engine.py", "from simcore.cli import simulate", "commands"),
        ("app/ui/controls.py", "from app.logic import upload", "ui-logic"),
        ("app/logic/scene_map.py", "from app.logic import controller", "controller"),
        ("app/payloads/cloud.py", "import simcore.reproduce", "payloads-no-reproduce"),
    ],
)
def test_a_contract_breaks_on_an_import_it_forbids(tmp_path, module, line, contract):
    """The copy with one import added inside a function of ``module``: ``contract`` breaks."""
    root = copy_of_the_packages(tmp_path)
    with open(root / module, "a", encoding="utf-8") as f:
        f.write(f"\n\ndef _added():\n    {line}\n")
    done = lint_imports(contract, root=root)
    assert done.returncode == 1
    assert "1 broken" in done.stdout


def circles_through_a_package(graph: grimp.ImportGraph) -> list[tuple[str, ...]]:
    """The chains by which a module that its package (``__init__``) imports imports it back."""
    found = []
    for package in sorted(graph.modules):
        for module in sorted(graph.find_modules_directly_imported_by(package)):
            if module.startswith(package + ".") and graph.chain_exists(module, package):
                found.append((package, *graph.find_shortest_chain(module, package)))
    return found


def test_the_circle_finder_finds_one_through_a_package(tmp_path, monkeypatch):
    (tmp_path / "pkg").mkdir()
    (tmp_path / "pkg" / "__init__.py").write_text("from pkg.a import x\n")
    (tmp_path / "pkg" / "a.py").write_text("from pkg import b\n")
    (tmp_path / "pkg" / "b.py").write_text("def f():\n    import pkg\n")
    monkeypatch.syspath_prepend(str(tmp_path))
    graph = grimp.build_graph("pkg", cache_dir=None)
    assert circles_through_a_package(graph) == [("pkg", "pkg.a", "pkg.b", "pkg")]


def test_no_module_imports_its_own_package_back():
    assert circles_through_a_package(grimp.build_graph("simcore", "app", cache_dir=None)) == []


def test_no_script_imports_the_commands():
    importers = []
    for path in sorted((ROOT / "scripts").rglob("*.py")):
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if isinstance(node, ast.Import):
                names = [alias.name for alias in node.names]
            elif isinstance(node, ast.ImportFrom) and node.module:
                names = [node.module] + [f"{node.module}.{alias.name}" for alias in node.names]
            else:
                continue
            if any(n == "simcore.cli" or n.startswith("simcore.cli.") for n in names):
                importers.append(path.name)
    assert importers == []


PROBE = r"""
import builtins, importlib, json, sys

front_end = set(sys.argv[1].split(","))
library = sys.argv[2].split(",")
importers = []
real_import = builtins.__import__

def spy(name, globals=None, locals=None, fromlist=(), level=0):
    who = (globals or {}).get("__name__", "")
    if level == 0 and name.partition(".")[0] in front_end and who.startswith("simcore"):
        importers.append([who, name])
    return real_import(name, globals, locals, fromlist, level)

builtins.__import__ = spy
import simcore
after_import = sorted(m for m in front_end if m in sys.modules)
for name in library:
    importlib.import_module(name)
for name in simcore.__all__:
    getattr(simcore, name)
print(json.dumps({"after_import": after_import, "library": library, "importers": importers,
                  "loaded": sorted(m for m in front_end - {"argparse"} if m in sys.modules)}))
"""


def test_the_library_loads_no_front_end_library_on_import():
    """``import simcore``, then every library module and public name: no matplotlib, Dask,
    pyarrow, h5py or laspy in ``sys.modules``, and no simcore module imports argparse (scipy and
    trimesh load argparse themselves, through ``numpy.testing`` and ``numpy.f2py``; that is
    theirs, so argparse is checked by importer)."""
    modules = grimp.build_graph("simcore", cache_dir=None).modules
    library = sorted(m for m in modules if m != "simcore" and not m.startswith("simcore.cli"))
    done = subprocess.run(
        [sys.executable, "-c", PROBE, ",".join(FRONT_END), ",".join(library)],
        capture_output=True,
        text=True,
        check=True,
        cwd=ROOT,
    )
    probe = json.loads(done.stdout)
    assert probe["after_import"] == []
    assert {"simcore.pipeline", "simcore.sweep.run", "simcore.reproduce"} <= set(probe["library"])
    assert probe["loaded"] == []
    assert probe["importers"] == []


def test_lmapd_help_does_not_load_the_imaging_chain():
    code = (
        "import sys; from simcore.cli import build_parser; build_parser(); "
        "print(sorted(m for m in ('numpy', 'simcore.pipeline', 'trimesh') if m in sys.modules))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert done.stdout.strip() == "[]"


def test_the_zygote_loads_no_framework_before_its_version_check():
    """``python -m app.server.zygote`` checks the framework releases in its ``__main__`` block:
    its module-level imports (the lines it shares with the launcher) load no trame, wslink or
    aiohttp, so that no patched framework module is imported before that check."""
    code = (
        "import sys, app.server.zygote; "
        "print(sorted(m for m in sys.modules if m.partition('.')[0] in "
        "('trame', 'trame_server', 'wslink', 'aiohttp')))"
    )
    done = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=ROOT
    )
    assert done.stdout.strip() == "[]"


def test_the_public_names_are_the_lazy_exports_and_resolve():
    import simcore

    assert set(simcore.__all__) == set(simcore._EXPORTS)
    assert simcore.Pipeline is __import__("simcore.pipeline").pipeline.Pipeline
    assert simcore.io.CLOUD_SUFFIXES == (".ply", ".las")  # a submodule by attribute
    with pytest.raises(AttributeError):
        simcore.no_such_name  # noqa: B018


def test_the_ui_takes_from_the_logic_only_the_names_of_its_package_interface():
    """app/ui takes from app/logic only the names app/logic/__init__.py declares for it
    (``__all__``): no constant or function of its own (its modules: the ui-logic contract)."""
    import app.logic

    names = []
    for path in sorted((ROOT / "app" / "ui").rglob("*.py")):
        package = list(path.relative_to(ROOT).parent.parts)  # where a relative import starts
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            base = package[: len(package) - (node.level - 1)] if node.level else []
            if ".".join(base + ([node.module] if node.module else [])) == "app.logic":
                names += [
                    (path.name, a.name) for a in node.names if a.name not in app.logic.__all__
                ]
    assert names == []
