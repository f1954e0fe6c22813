"""A new tab's first picture: the page does only the work that picture needs before it
(docs/performance.md, "A new tab's first picture"). The charts' library (plotly's 4.6 MB bundle)
is asked for only once the first frame is on screen, and the charts then draw; the scripts the
page loads before its first frame stay within a byte budget; the drawer's panels of a choice not
made (the Geiger-mode receiver's controls, the Sun's, fly-around's) are not built until chosen.
The checks are orders of events and counts of bytes and elements, never times."""

from __future__ import annotations

from contextlib import contextmanager

import pytest
from support.launch import wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

# The page's scripts before its first frame: Vue, trame's client, Vuetify, vtk.js and the page's
# own files come to about 2.6 MB; plotly's bundle alone is 4.6 MB.
SCRIPT_BYTES_BEFORE_FIRST_FRAME = 3_500_000

# every WebGL clear, logged by its own hook at the prototype (installed before the page's files)
CLEAR_LOG = """(() => {
  window.clearLog = [];
  const clear = WebGL2RenderingContext.prototype.clear;
  WebGL2RenderingContext.prototype.clear = function (...args) {
    window.clearLog.push({ canvas: this.canvas, t: performance.now(),
                           size: `${this.canvas.width}x${this.canvas.height}` });
    return clear.apply(this, args);
  };
})()"""
VIEW_CLEARS = """() => {
  const shown = window.lmapdFrames[0].t;
  return ['scene_view', 'cloud_view'].map((ref) => {
    const canvas = window.trame.refs[ref].$.provides.view.openglRenderWindow.getCanvas();
    const size = `${canvas.width}x${canvas.height}`;
    const mine = window.clearLog.filter((c) => c.canvas === canvas);
    const sized = mine.filter((c) => c.size === size && c.t <= shown);
    return { size, sizes: mine.map((c) => c.size), drawnBefore: sized.length > 0,
             sizedBefore: sized.length };
  });
}"""

RESOURCES = """() => performance.getEntriesByType('resource')
  .filter((r) => r.initiatorType === 'script' || r.name.endsWith('.js'))
  .map((r) => ({ name: r.name, start: r.startTime, bytes: r.encodedBodySize }))"""


@contextmanager
def second_tab_logging_clears(page, app_url):
    """A second tab of the app (its WebGL clears logged: ``CLEAR_LOG``), opened once the first
    has settled (the scene's frame is ready), up to its first frame; closed after."""
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    other = page.context.new_page()
    try:
        other.add_init_script(CLEAR_LOG)
        other.goto(app_url)
        wait_first_frame(other)
        yield other
    finally:
        other.close()


def test_the_charts_library_loads_after_the_first_frame_and_the_charts_draw(page, app_url):
    page.goto(app_url)
    wait_first_frame(page)
    # a drawn trace (on the shared test server an earlier test may leave a pixel selected whose
    # echo is empty: its trace, first in the chart, has nothing to draw)
    page.wait_for_selector(
        ".waveform-box .js-plotly-plot .scatterlayer .trace >> visible=true", timeout=120_000
    )
    page.wait_for_selector(".snr-box .js-plotly-plot", timeout=120_000)
    first = page.evaluate("() => window.lmapdFrames[0].t")
    charts = page.evaluate("() => window.lmapdCharts")
    scripts = page.evaluate(RESOURCES)
    plotly = [s for s in scripts if "plotly" in s["name"]]
    assert len(plotly) == 1, plotly  # asked for once, by the charts' loader
    assert charts["requested"] >= first and plotly[0]["start"] >= first, (charts, plotly, first)
    assert charts["loaded"] >= charts["requested"]
    before = [s for s in scripts if s["start"] < first]
    assert sum(s["bytes"] for s in before) < SCRIPT_BYTES_BEFORE_FIRST_FRAME, before
    assert any("trame-vtk" in s["name"] for s in before)  # the views' library is among them


def test_a_choices_own_controls_are_built_only_once_chosen(page, app_url):
    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    hidden = (".gm-controls", ".sun-manual-controls", ".flyaround-panel")
    assert [page.locator(sel).count() for sel in hidden] == [0, 0, 0]
    page.locator(".receiver-gm").click()
    page.locator(".gm-controls .v-slider").first.wait_for()
    page.locator(".sun-manual").click()
    page.locator(".sun-manual-controls .v-slider").first.wait_for()
    page.locator(".receiver-lm").click()
    page.locator(".gm-controls").wait_for(state="detached")
    wait_settled(page)


def test_the_first_frame_is_shown_only_after_each_view_drew_it_at_its_size(page, app_url):
    """A page opened on a scene whose frame is ready gets that frame while it mounts, before its
    views exist; vtk.js first renders a new view empty at 300 x 300 pixels, then at its own
    size with the frame's data. The frame is logged (and reported to the server's pacing) after
    both views drew it at their size (app/static/frame.js), never after the empty renders."""
    with second_tab_logging_clears(page, app_url) as other:
        first = other.evaluate("() => window.lmapdFrames[0]")
        assert first["key"][0] == "g" and first["applied"] < first["t"], first
        for view in other.evaluate(VIEW_CLEARS):
            assert view["size"] != "300x300" and "300x300" in view["sizes"], view
            assert view["drawnBefore"], view


def test_each_view_draws_the_first_frame_once_at_its_size(page, app_url):
    """A new vtk.js view resets its camera as it mounts and again 100 ms later (trame-vtk's
    VtkView); the page's camera reset goes to the state's home camera, so the second would draw
    both views once more with the same picture (with WebGL in software, about 0.15 s of a new
    tab's first picture). The page calls it off (app/static/frame.js, setCamera): up to the
    first frame on screen, each view has drawn at its size once."""
    with second_tab_logging_clears(page, app_url) as other:
        wait_settled(other)
        for view in other.evaluate(VIEW_CLEARS):
            assert view["sizedBefore"] == 1, view


# when the first of each selector's elements appeared in the page [ms, page clock]
APPEARED = """(() => {
  window.appeared = {};
  new MutationObserver(() => {
    const sels = ['.controls', '.array-card', '.waveform-card', '.stats-card', '.scene-card'];
    for (const sel of sels) {
      if (!(sel in window.appeared) && document.querySelector(sel)) {
        window.appeared[sel] = performance.now();
      }
    }
  }).observe(document, { subtree: true, childList: true });
})()"""


def test_the_panels_below_the_views_are_built_after_the_first_frame(page, app_url):
    """The picture a new tab waits for is the two 3D views: the array image, the waveforms and
    the stats are built with the drawer's controls, after the first frame is on screen."""
    page.add_init_script(APPEARED)
    page.goto(app_url)
    wait_first_frame(page)
    shown = page.evaluate("() => window.lmapdFrames[0].t")
    appeared = page.evaluate("() => window.appeared")
    assert appeared[".scene-card"] < shown, appeared
    for later in (".controls", ".array-card", ".waveform-card", ".stats-card"):
        assert appeared[later] >= shown, (later, appeared, shown)


VIEW_CONTEXTS = """() => ({
  software: window.trame.utils.lmapd.softwareGL(),
  antialias: ['scene_view', 'cloud_view'].map((ref) => window.trame.refs[ref].$.provides.view
    .openglRenderWindow.getContext().getContextAttributes().antialias),
})"""

# a browser whose WebGL names a GPU (the test's Chromium draws in software, SwiftShader)
A_GPU = """(() => {
  for (const proto of [WebGLRenderingContext.prototype, WebGL2RenderingContext.prototype]) {
    const getParameter = proto.getParameter;
    proto.getParameter = function (name) {
      return name === 0x9246  // UNMASKED_RENDERER_WEBGL
        ? 'ANGLE (NVIDIA, NVIDIA GeForce RTX 3060 Direct3D11 vs_5_0 ps_5_0, D3D11)'
        : getParameter.call(this, name);
    };
  }
})()"""


def test_views_drawn_in_software_are_not_multisampled(page, app_url):
    """WebGL in software (this test's Chromium: SwiftShader) draws the views without
    antialiasing, its costliest option there (app/static/frame.js; docs/serving.md)."""
    page.goto(app_url)
    wait_first_frame(page)
    assert page.evaluate(VIEW_CONTEXTS) == {"software": True, "antialias": [False, False]}


def test_views_drawn_on_a_gpu_keep_antialiasing(page, app_url):
    page.add_init_script(A_GPU)
    page.goto(app_url)
    wait_first_frame(page)
    assert page.evaluate(VIEW_CONTEXTS) == {"software": False, "antialias": [True, True]}
