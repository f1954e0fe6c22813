"""The page's own scripts and styles (app/static/, served by app.ui.static): each script parses
(``node --check``, as ``make lint`` runs it), each style sheet is well formed, every file of the
folder is one the page loads, the page's server serves them under a name that changes with their
contents, and the waveform chart's measuring cursor (cursor.js, run in Node.js on a stand-in chart)
gives its two cursors, their difference and its lines."""

from __future__ import annotations

import json
import re
import shutil
import subprocess
from pathlib import Path

import pytest

from app.ui import static

NODE = shutil.which("node")


def test_every_file_of_the_folder_is_one_the_page_loads():
    files = sorted(p.name for p in static.STATIC_DIR.iterdir() if p.is_file())
    assert files == sorted((*static.SCRIPTS, *static.STYLES))


@pytest.mark.parametrize("name", static.SCRIPTS)
def test_each_script_parses(name):
    assert NODE, "the scripts' check needs Node.js (Debian's nodejs: .ci/run installs it)"
    done = subprocess.run(
        [NODE, "--check", str(static.STATIC_DIR / name)], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr


def test_the_parse_check_finds_a_broken_script(tmp_path):
    assert NODE
    broken = tmp_path / "broken.js"
    broken.write_text("window.x = { a: 1, ;\n", encoding="utf-8")
    done = subprocess.run([NODE, "--check", str(broken)], capture_output=True, text=True)
    assert done.returncode != 0 and "SyntaxError" in done.stderr


def css_problems(text: str) -> list[str]:
    """What makes a style sheet malformed here: an unclosed comment, unbalanced braces, or a
    declaration that is not ``name: value`` (a missing colon shows as one, and so does a missing
    semicolon before a declaration: two colons; no value here holds a colon)."""
    problems = []
    if text.count("/*") != text.count("*/"):
        return ["an unclosed comment"]
    text = re.sub(r"/\*.*?\*/", "", text, flags=re.S)
    depth = 0
    body = ""
    for char in text:
        if char == "{":
            depth += 1
            body = ""
        elif char == "}":
            depth -= 1
            if depth < 0:
                return ["a '}' without its '{'"]
            for declaration in filter(None, (d.strip() for d in body.split(";"))):
                if not re.fullmatch(r"-?[a-z][a-z-]*\s*:\s*[^:]+", declaration):
                    problems.append(f"not a declaration: {declaration!r}")
            body = ""
        else:
            body += char
    if depth != 0:
        problems.append("unbalanced braces")
    return problems


@pytest.mark.parametrize("name", static.STYLES)
def test_each_style_sheet_is_well_formed(name):
    assert css_problems((static.STATIC_DIR / name).read_text(encoding="utf-8")) == []


def test_the_style_check_finds_a_missing_semicolon_and_an_open_brace():
    assert css_problems(".a { color: red background: blue; }") != []
    assert css_problems(".a { color: red; ") == ["unbalanced braces"]
    assert css_problems(".a { color: red; } /* open") == ["an unclosed comment"]
    assert css_problems("@media (max-width: 600px) { .a { color: red; } }") == []


def test_the_module_serves_the_folder_under_a_name_of_its_contents(tmp_path):
    copy = tmp_path / "static"
    shutil.copytree(static.STATIC_DIR, copy)
    module = static.module(copy)
    (name,) = module["serve"]
    assert module["serve"][name] == str(copy) and re.fullmatch(r"__lmapd_[0-9a-f]{12}", name)
    assert module["scripts"] == [f"{name}/{file}" for file in static.SCRIPTS]
    assert module["styles"] == [f"{name}/{file}" for file in static.STYLES]
    assert static.served_name(copy) == static.served_name(static.STATIC_DIR)
    (copy / "page.css").write_text(Path(copy / "page.css").read_text() + "\n.x { color: red; }\n")
    assert static.served_name(copy) != static.served_name(static.STATIC_DIR)


def test_the_page_loads_its_files_after_the_widget_libraries_styles():
    from trame.app import get_server

    from app.ui.layout import build_layout

    server = get_server("static-files-test", client_type="vue3")
    build_layout(server)
    module = static.module()
    (name,) = module["serve"]
    assert server.serve[name] == str(static.STATIC_DIR)
    scripts, styles = server.state.trame__scripts, server.state.trame__styles
    assert [s for s in scripts if s.startswith(name)] == module["scripts"]
    assert styles[-len(module["styles"]) :] == module["styles"]  # last: these rules win
    assert any("vuetify" in s for s in styles[: -len(module["styles"])])


def test_plotly_is_served_but_loaded_by_the_charts_loader_not_before_the_page_mounts():
    from trame.app import get_server
    from trame_plotly import module as plotly_module

    from app.ui import charts
    from app.ui.layout import build_layout

    server = get_server("charts-defer-test", client_type="vue3")
    build_layout(server)
    (folder,) = plotly_module.serve
    assert server.serve[folder] == plotly_module.serve[folder]  # still served
    assert not set(plotly_module.scripts) & set(server.state.trame__scripts)
    plugins = [u if isinstance(u, str) else u[0] for u in server.state.trame__vue_use]
    assert charts.PLUGIN not in plugins
    (loader,) = [
        u for u in server.state.trame__vue_use if not isinstance(u, str) and u[0] == charts.LOADER
    ]
    assert loader[1] == {"scripts": list(plotly_module.scripts)}


CURSOR_HARNESS = r"""
const fs = require('fs');
const vm = require('vm');
const gd = { layout: { shapes: [{ name: 'threshold' }] } };
const relayouts = [];
global.window = { trame: { utils: {} }, Plotly: {
  relayout: (el, update) => { relayouts.push(update); el.layout = { ...el.layout, ...update }; },
} };
global.document = { querySelector: (selector) => (selector.includes('waveform-box') ? gd : null) };
vm.runInThisContext(fs.readFileSync(process.argv[2], 'utf8'));
const cursor = window.trame.utils.lmapdCursor;
const names = () => gd.layout.shapes.map((s) => `${s.name}${s.x0 === undefined ? '' : '@' + s.x0}`);
const out = {};
out.a = cursor.click({ points: [{ x: 3335.64 }] });
out.ab = cursor.click({ points: [{ x: 3344.8125 }] });
out.nothing = cursor.click({ points: [] });
out.shapes_ab = names();
gd.layout = { shapes: [{ name: 'threshold' }] };  // a new plot: the cursors dropped
const before = relayouts.length;
cursor.redraw();
out.redrawn = names();
cursor.redraw();  // already drawn: no relayout
out.relayouts_by_redraw = relayouts.length - before;
out.again = cursor.click({ points: [{ x: 100 }] });
out.cleared = cursor.clear();
out.shapes_cleared = names();
console.log(JSON.stringify(out));
"""


def test_the_measuring_cursor_gives_a_then_b_and_their_difference(tmp_path):
    assert NODE
    harness = tmp_path / "harness.js"
    harness.write_text(CURSOR_HARNESS, encoding="utf-8")
    done = subprocess.run(
        [NODE, str(harness), str(static.STATIC_DIR / "cursor.js")], capture_output=True, text=True
    )
    assert done.returncode == 0, done.stderr
    out = json.loads(done.stdout)
    c = 299792458.0

    def where(t_ns: float) -> str:
        return f"{t_ns:,.2f} ns ({t_ns * 1e-9 * c / 2:,.3f} m)"

    a, b = 3335.64, 3344.8125
    assert out["a"] == f"A: {where(a)}"
    gap = f"{b - a:,.2f} ns, {(b - a) * 1e-9 * c / 2:,.3f} m in range"
    assert out["ab"] == f"A: {where(a)}, B: {where(b)}; B − A: {gap}"
    assert out["nothing"] == out["ab"]  # a click beside the traces changes nothing
    assert out["shapes_ab"] == ["threshold", f"cursor@{a}", f"cursor@{b}"]  # the chart's kept
    assert out["redrawn"] == out["shapes_ab"] and out["relayouts_by_redraw"] == 1
    assert out["again"] == f"A: {where(100.0)}"  # a third click starts again with A
    assert out["cleared"] == "" and out["shapes_cleared"] == ["threshold"]
