"""docs/api.md runs: its python blocks in order in one namespace (like notebook cells), in a
temporary folder; its toml blocks parse, and the sweep file among them is a valid sweep.

pyvista's ``Plotter.show`` is replaced by a recorder: the block builds the PolyData and the
plotter for real, but nothing is rendered (no display or EGL on CI); the test checks that the
shown cloud holds every point with every attribute. The blocks build on each other, like notebook
cells: run the whole file (selecting one block with -k leaves it without its predecessors).
"""

from __future__ import annotations

import os
import re
import tomllib
from pathlib import Path

import numpy as np
import pytest

from simcore.pointcloud import ATTRIBUTES
from simcore.sweep import sweep_from_dict

DOC = Path(__file__).resolve().parent.parent / "docs" / "api.md"
FENCE = re.compile(r"^```(\w+)[^\n]*\n(.*?)^```", re.MULTILINE | re.DOTALL)
HEADING = re.compile(r"^#+ (.+)$", re.MULTILINE)


def blocks(language: str) -> list[tuple[str, str]]:
    """(id, code) of every fenced block in ``language``; the id names the section it is in."""
    text = DOC.read_text(encoding="utf-8")
    found = []
    for match in FENCE.finditer(text):
        if match.group(1) != language:
            continue
        headings = HEADING.findall(text[: match.start()])
        section = re.sub(r"\W+", "-", headings[-1].lower()).strip("-") if headings else "top"
        found.append((f"{len(found) + 1}-{section}", match.group(2)))
    return found


PYTHON = blocks("python")
TOML = blocks("toml")


@pytest.fixture(scope="module")
def notebook(tmp_path_factory):
    """One namespace for all python blocks, run in a temporary working folder; pyvista's
    ``Plotter.show`` records the plotter instead of rendering."""
    import pyvista as pv

    shown = []
    mp = pytest.MonkeyPatch()
    mp.setattr(pv, "OFF_SCREEN", True)
    mp.setattr(pv.Plotter, "show", lambda self, *a, **k: shown.append(self))
    cwd = os.getcwd()
    os.chdir(tmp_path_factory.mktemp("api_docs"))
    try:
        yield {"__name__": "api_docs", "shown": shown}
    finally:
        os.chdir(cwd)
        mp.undo()


def test_the_doc_has_an_example_for_each_part_of_the_api():
    code = "\n".join(c for _, c in PYTHON)
    for call in (
        "simcore.simulate(",
        "result.waveform(",
        "io.write_cloud(",
        "io.write_waveforms(",
        "run_sweep(",
        "run_flyaround(",
        "pv.PolyData(",
    ):
        assert call in code, call


@pytest.mark.parametrize(("block", "code"), PYTHON, ids=[i for i, _ in PYTHON])
def test_each_python_block_runs(notebook, block, code):
    exec(compile(code, f"{DOC.name} block {block}", "exec"), notebook)


def test_the_shown_cloud_has_every_point_and_attribute(notebook):
    assert len(notebook["shown"]) == 1, "the pyvista block calls plotter.show() once"
    plotter = notebook["shown"][0]
    result = notebook["result"]
    mesh = plotter.mesh  # the last mesh added: the cloud
    np.testing.assert_allclose(mesh.points, result.points.astype(mesh.points.dtype))
    for name, _ in ATTRIBUTES:
        np.testing.assert_array_equal(mesh.point_data[name], result.attributes[name], name)
    assert plotter.mapper.array_name == "range_m"  # coloured by range


@pytest.mark.parametrize(("block", "text"), TOML, ids=[i for i, _ in TOML])
def test_each_toml_block_parses_and_the_sweep_file_is_valid(block, text):
    data = tomllib.loads(text)
    if "grid" in data or "list" in data:
        sweep = sweep_from_dict(data, source=f"{DOC.name} block {block}")
        assert len(sweep) == 3 * 3 * 3 + 2
