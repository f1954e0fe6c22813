"""The package layout of issue 14: the physics library loads no front-end library, the commands
live in ``simcore/cli/`` and nothing else imports them, and no module imports itself in a circle.

The import graph is read from the source (every ``import`` of every module, those inside functions
included, ``if TYPE_CHECKING:`` blocks left out), so a circle held together by a function-level
import is found as surely as one at the top of a module.
"""

from __future__ import annotations

import ast
import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent
FRONT_END = ("matplotlib", "dask", "distributed", "pyarrow", "h5py", "laspy", "argparse")


def module_name(path: Path) -> str:
    """``simcore/sweep/run.py`` -> ``simcore.sweep.run``; an ``__init__`` is its package."""
    parts = list(path.relative_to(ROOT).with_suffix("").parts)
    return ".".join(parts[:-1] if parts[-1] == "__init__" else parts)


def project_modules(*packages: str) -> dict[str, Path]:
    """Every module of ``packages`` (dotted name -> file)."""
    return {module_name(p): p for pkg in packages for p in sorted((ROOT / pkg).rglob("*.py"))}


def imported_modules(name: str, path: Path, modules: dict[str, Path]) -> set[str]:
    """The project modules that module ``name`` imports, relative imports resolved.

    ``import X`` is an edge to ``X``; ``from X import a`` to ``X.a`` when that is a module, else to
    ``X``. Every import counts: those inside functions and under ``if TYPE_CHECKING:`` too (a
    type-only import is still a dependency of the module's design).
    """
    package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
    found = set()
    for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
        if isinstance(node, ast.Import):
            found.update(alias.name for alias in node.names)
        elif isinstance(node, ast.ImportFrom):
            if node.level:
                base = package[: len(package) - (node.level - 1)]
                source = ".".join(base + ([node.module] if node.module else []))
            else:
                source = node.module or ""
            for alias in node.names:
                sub = f"{source}.{alias.name}"
                found.add(sub if sub in modules else source)
    return {n for n in found if n in modules and n != name}


def import_graph(*packages: str) -> dict[str, set[str]]:
    """Module -> the project modules it imports (a package's implicit import of its parent
    package is no edge: it is how packages work, not a dependency the code chose)."""
    modules = project_modules(*packages)
    return {name: imported_modules(name, path, modules) for name, path in modules.items()}


def cycles(graph: dict[str, set[str]]) -> list[list[str]]:
    """The strongly connected components with more than one module (Tarjan), each sorted."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on_stack: set[str] = set()
    found = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on_stack.add(v)
        for w in sorted(graph.get(v, ())):
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on_stack:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            component = []
            while True:
                w = stack.pop()
                on_stack.discard(w)
                component.append(w)
                if w == v:
                    break
            if len(component) > 1:
                found.append(sorted(component))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return found


def test_the_cycle_finder_finds_a_circle_through_a_function_level_import(tmp_path, monkeypatch):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    (pkg / "__init__.py").write_text("")
    (pkg / "a.py").write_text("from . import b\n")
    (pkg / "b.py").write_text("def f():\n    from .a import g\n")
    (pkg / "c.py").write_text(
        "from typing import TYPE_CHECKING\nif TYPE_CHECKING:\n    from . import d\n"
    )
    (pkg / "d.py").write_text("from pkg.c import x\nfrom pkg import a\n")
    monkeypatch.setattr(sys.modules[__name__], "ROOT", tmp_path)
    assert cycles(import_graph("pkg")) == [["pkg.a", "pkg.b"], ["pkg.c", "pkg.d"]]


def test_no_module_of_simcore_imports_itself_through_a_circle():
    assert cycles(import_graph("simcore")) == []


def test_no_module_of_the_app_imports_itself_through_a_circle():
    assert cycles(import_graph("app")) == []


# the app's floors, lowest first: a module may import its own floor and those below, never above
APP_FLOORS = (
    ("app.state", "app.runner"),
    ("app.payloads", "app.engine"),
    ("app.logic",),
    ("app.ui",),
    # the app joined (app.main) and served (app.server: the door, the connections, the state sync
    # and the framework patches; the launcher: a process per session, started or forked from the
    # zygote)
    ("app.main", "app.__main__", "app.server"),
)


def app_floor(name: str) -> int:
    for level, prefixes in enumerate(APP_FLOORS):
        if any(name == p or name.startswith(p + ".") for p in prefixes):
            return level
    raise AssertionError(f"{name} is on no floor of APP_FLOORS: place it")


def test_the_app_is_engine_below_logic_below_ui_and_logic_children_never_import_the_parent():
    graph = import_graph("app")
    upward = [
        (a, b)
        for a, imported in graph.items()
        if a != "app"
        for b in imported
        if b != "app" and app_floor(b) > app_floor(a)
    ]
    assert upward == []
    parent = "app.logic.controller"
    children = [a for a, imported in graph.items() if parent in imported and a != "app.main"]
    assert children == []


def test_nothing_outside_simcore_cli_imports_the_commands():
    importers = []
    for package in ("simcore", "app", "scripts"):
        for name, path in project_modules(package).items():
            if name == "simcore.cli" or name.startswith("simcore.cli."):
                continue
            names = imported_modules(name, path, project_modules("simcore"))
            if any(n == "simcore.cli" or n.startswith("simcore.cli.") for n in names):
                importers.append(name)
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
    library = [m for m in project_modules("simcore") if not m.startswith("simcore.cli")]
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


# simcore's floors, lowest first: a module may import its own floor and those below, never above
SIMCORE_FLOORS = (
    # foundations: constants, errors, files, caches, threads, materials, the calibration shapes,
    # the plug-in points
    (
        "simcore._version",
        "simcore._assets",
        "simcore._draco_probe",
        "simcore.constants",
        "simcore.errors",
        "simcore.tomlfile",
        "simcore.cache",
        "simcore.parallel",
        "simcore.gltf",
        "simcore.mesh_headers",
        "simcore.calibration",
        "simcore.illumination",
        "simcore.materials",
        # the receivers' registry and what a receiver declares: the scene reads them for the valid
        # kinds and the receivers' sections
        "simcore.plugins",
    ),
    # the scene, the orbits and the Sun, the trajectories' poses, what a stage is, the pulse
    (
        "simcore.scene",
        "simcore.orbit",
        "simcore.sun",
        "simcore.trajectory",
        "simcore.stage",
        "simcore.pulse",
    ),
    # the chain's physics up to each pixel's detections: target, rays and hits, echo, background
    # light, the receivers (their declarations and their physics)
    (
        "simcore.target",
        "simcore.target_mesh",
        "simcore.mesh_distance",
        "simcore.target_model",
        "simcore.geometry",
        "simcore.echo",
        "simcore.background",
        "simcore.receivers",
    ),
    # the point cloud and its quality against the ground truth
    ("simcore.pointcloud", "simcore.quality"),
    # the pipeline, its result, the files it writes
    ("simcore.pipeline", "simcore.result", "simcore.io"),
    # runs of many frames and their analyses
    (
        "simcore.sweep",
        "simcore.atlas",
        "simcore.flyaround",
        "simcore.tracking",
        "simcore.bag",
        "simcore.compare",
        "simcore.reproduce",
        "simcore.design",
    ),
    # the commands, and the package's public names (lazy re-exports of the floors below)
    ("simcore.cli", "simcore"),
)


def simcore_floor(name: str) -> int:
    for level, prefixes in enumerate(SIMCORE_FLOORS):
        if any(name == p or name.startswith(p + ".") for p in prefixes if p != "simcore"):
            return level
    if name == "simcore":
        return len(SIMCORE_FLOORS) - 1
    raise AssertionError(f"{name} is on no floor of SIMCORE_FLOORS: place it")


def upward_imports(graph: dict[str, set[str]]) -> list[tuple[str, str]]:
    """The (importer, imported) pairs of ``graph`` whose imported module is on a higher floor."""
    return sorted(
        (a, b)
        for a, imported in graph.items()
        for b in imported
        if simcore_floor(b) > simcore_floor(a)
    )


def test_the_floor_rule_finds_the_receivers_old_arrow_up_to_the_point_cloud():
    # the arrow that receivers/gm_apd.py had (its first-photon cloud), now gone
    graph = {"simcore.receivers.gm_apd.detection": {"simcore.pointcloud", "simcore.echo"}}
    assert upward_imports(graph) == [("simcore.receivers.gm_apd.detection", "simcore.pointcloud")]


def test_simcore_never_imports_upwards():
    assert upward_imports(import_graph("simcore")) == []


def test_simcore_s_packages_import_each_other_through_no_circle():
    """Drawn at package granularity (``simcore.scene.keys`` is ``simcore.scene``), the arrows run
    one way: the scene reads the receivers' registry from ``simcore.plugins``, below it, never from
    ``simcore.receivers``, which reads the scene's fields."""
    packages: dict[str, set[str]] = {}
    for a, imported in import_graph("simcore").items():
        for b in imported:
            top_a, top_b = ".".join(a.split(".")[:2]), ".".join(b.split(".")[:2])
            if top_a != top_b:
                packages.setdefault(top_a, set()).add(top_b)
    assert "simcore.receivers" not in packages["simcore.scene"]
    assert cycles(packages) == []


def test_the_apps_payloads_import_no_reproduction_code():
    simcore_modules = project_modules("simcore")
    found = []
    for name, path in project_modules("app").items():
        if name.startswith("app.payloads"):
            for imported in imported_modules(name, path, simcore_modules):
                if imported == "simcore.reproduce" or imported.startswith("simcore.cli.reproduce"):
                    found.append((name, imported))
    assert found == []


def test_the_ui_reads_the_logic_only_through_its_package_interface():
    """app/ui takes from app/logic only the names app/logic/__init__.py declares for it
    (``__all__``): no logic module, constant or function of its own."""
    import app.logic

    modules = project_modules("app")
    internals, names = [], []
    for name, path in modules.items():
        if not name.startswith("app.ui"):
            continue
        internals += [
            (name, m) for m in imported_modules(name, path, modules) if m.startswith("app.logic.")
        ]
        package = name.split(".") if path.name == "__init__.py" else name.split(".")[:-1]
        for node in ast.walk(ast.parse(path.read_text(encoding="utf-8"))):
            if not isinstance(node, ast.ImportFrom):
                continue
            base = package[: len(package) - (node.level - 1)] if node.level else []
            source = ".".join(base + ([node.module] if node.module else []))
            if source == "app.logic":
                names += [(name, a.name) for a in node.names if a.name not in app.logic.__all__]
    assert internals == []
    assert names == []
