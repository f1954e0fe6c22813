"""The charts' library loads after the page's first picture.

The charts are trame-plotly's (``trame.widgets.plotly.Figure``, the Vue component TramePlotly).
Its module puts plotly's whole bundle (4.6 MB) among the scripts a page loads before it mounts,
and evaluating it was the largest single cost of a new tab's first picture (about 0.6 s of the
page's CPU here, docs/serving.md). :func:`defer_plotly` takes that script and its Vue plugin
off the page's start-up lists (the folder stays served) and has the page's own plugin,
``trame.utils.lmapdCharts`` (``app/static/charts.js``), register TramePlotly as an async
component that loads the script once the first frame is on screen and the server has no other
on its way (such as the chosen preset's after a preview). The charts are the same component with
the same properties and events; they appear a moment after the first frame.

Checked against trame-plotly 3.1.2 (its module: ``scripts``, ``vue_use = ["trame_plotly"]``, the
UMD global ``trame_plotly`` whose ``install`` registers TramePlotly) and trame-server 4.1
(``enable_module`` appends a module's scripts and Vue plugins to ``trame__scripts`` and
``trame__vue_use``, which the page reads before it mounts).
"""

from __future__ import annotations

from trame_plotly import module as plotly_module

PLUGIN = "trame_plotly"  # the Vue plugin trame-plotly's module names (window.trame_plotly)
LOADER = "trame.utils.lmapdCharts"  # app/static/charts.js


def _plugin_name(entry) -> str:
    return entry[0] if isinstance(entry, list | tuple) else entry


def defer_plotly(server) -> None:
    """Take plotly's script and plugin off ``server``'s start-up lists and hand them to the
    page's loader (call once the layout, with its charts, is built, before the page's own files
    are enabled: ``app.ui.static.enable`` serves charts.js)."""
    server = server.root_server
    scripts = list(plotly_module.scripts)
    server.enable_module(plotly_module)  # served (a no-op if a chart enabled it already)
    state = server.state
    state.trame__scripts = [s for s in state.trame__scripts if s not in scripts]
    state.trame__vue_use = [u for u in state.trame__vue_use if _plugin_name(u) != PLUGIN]
    server.enable_module({"vue_use": [(LOADER, {"scripts": scripts})]})
