"""The page: app bar (title, busy indicator, frame info), drawer (controls), the views in a grid,
messages, and a footer with the NASA credit."""

from __future__ import annotations

from trame.ui.vuetify3 import VAppLayout
from trame.widgets import client, html
from trame.widgets import vuetify3 as v3

from app.ui import classroom, controls, design, glossary, lessons, panels, views3d
from app.ui.widgets import html_attributes

# After the page applied a frame, wait until it is on screen, then tell the server (frame pacing)
# and keep a log of those times for the benchmark (window.lmapdFrames). On screen: a WebGL canvas
# reaches the screen in the compositor's commit after vtk.js rendered it (with software WebGL the
# commit waits for the rendering and reads the canvas back), so the time is taken two animation
# frames after the views' last render (each render is stamped), not two after the state arrived.
# Vue templates cannot reach browser globals, so the helper hangs on trame.utils.
FRAME_SCRIPT = """
window.trame.utils.lmapd = {
  lastRender: 0,
  watchViews() {
    for (const ref of ['scene_view', 'cloud_view']) {
      const view = window.trame.refs[ref];
      const rw = view && view.$ && view.$.provides && view.$.provides.view
        && view.$.provides.view.renderWindow;
      if (!rw || rw.lmapdStamped) continue;
      const render = rw.render;
      rw.render = (...args) => { this.lastRender = performance.now(); return render(...args); };
      rw.lmapdStamped = true;
    }
  },
  frameShown(key) {
    if (!key) return;
    const applied = performance.now();
    this.watchViews();
    let mark = applied;
    const onScreen = (tries) => requestAnimationFrame(() => requestAnimationFrame(() => {
      if (this.lastRender > mark && tries > 0) {  // a view rendered meanwhile: its commit next
        mark = performance.now();
        onScreen(tries - 1);
        return;
      }
      const kind = key[0] === 'p' ? 'preview' : 'preset', t = performance.now();
      (window.lmapdFrames = window.lmapdFrames || []).push({ key, kind, applied, t });
      window.trame.trigger('frame_shown', [key]);
    }));
    setTimeout(() => onScreen(8), 0);
  },
};
"""
FRAME_SHOWN = "trame.utils.lmapd && trame.utils.lmapd.frameShown($event)"

# Accessible names and spoken values where the widgets cannot set them: Vuetify puts a slider's
# aria-label on its wrapper, not on the thumb (role "slider") a screen reader reads, and a text
# field's input points to a label that does not exist, a select's box has no name; plotly's tool
# buttons are unnamed links.
# A control's box carries data-a11y-name / -unit / -log (app.ui.widgets.a11y_attributes): this
# names its thumb and input and keeps the thumb's aria-valuetext the value with its unit
# ("500 m", not the log10 position 2.699). Re-applied, at most once per animation frame,
# whenever the page changes.
A11Y_SCRIPT = """
(() => {
  const spoken = (box, thumb) => {
    let v = Number(thumb.getAttribute('aria-valuenow'));
    if (box.dataset.a11yLog === '1') v = Number((10 ** v).toPrecision(3));
    const key = box.dataset.stateKey, held = key ? Number(window.trame.state.get(key)) : NaN;
    if (Number.isFinite(held)) v = held;  // the value itself, not the thumb's rounded place
    const unit = box.dataset.a11yUnit;
    return `${Number(v.toPrecision(6))}${unit ? ' ' + unit : ''}`;
  };
  const set = (el, name, value) => {
    if (el.getAttribute(name) !== value) el.setAttribute(name, value);
  };
  const label = () => {
    document.querySelectorAll('[data-a11y-name]').forEach((box) => {
      const name = box.dataset.a11yName, unit = box.dataset.a11yUnit;
      box.querySelectorAll('[role=slider]').forEach((thumb) => {
        set(thumb, 'aria-label', name);
        set(thumb, 'aria-valuetext', spoken(box, thumb));
      });
      box.querySelectorAll('input').forEach((input) => {
        const by = input.getAttribute('aria-labelledby');
        if (by && !document.getElementById(by)) input.removeAttribute('aria-labelledby');
        set(input, 'aria-label', `${name}${unit ? ' in ' + unit : ''}`);
      });
    });
    document.querySelectorAll('.v-field[role=combobox]').forEach((field) => {
      const text = (field.querySelector('label') || {}).textContent;
      if (text && text.trim()) set(field, 'aria-label', text.trim());
    });
    document.querySelectorAll('a.modebar-btn').forEach((a) => {
      set(a, 'aria-label', a.dataset.title || 'chart tool');
    });
  };
  let pending = false;
  new MutationObserver(() => {
    if (pending) return;
    pending = true;
    requestAnimationFrame(() => { pending = false; label(); });
  }).observe(document.body, {
    subtree: true, childList: true, attributes: true, attributeFilter: ['aria-valuenow'],
  });
  label();
})();
"""

# The 3D views do not capture the page's scroll: the mouse wheel over a view scrolls the page
# unless Ctrl (or Cmd, or a trackpad pinch) is held or the view was clicked (until the pointer
# leaves it); a wheel event meant for the page never reaches vtk.js's interactor. A view clicked
# or tapped is "active" (a thin blue frame), and only then does a finger swipe over it rotate it.
VIEW_SCROLL_SCRIPT = """
(() => {
  const viewOf = (e) => (e.target && e.target.closest ? e.target.closest('.vtk-box') : null);
  document.addEventListener('pointerdown', (e) => {
    const box = viewOf(e);
    document.querySelectorAll('.vtk-box.view-active').forEach((b) => {
      if (b !== box) b.classList.remove('view-active');
    });
    if (box) box.classList.add('view-active');
  }, true);
  document.addEventListener('pointerout', (e) => {
    const box = viewOf(e);
    if (box && e.pointerType === 'mouse' && !box.contains(e.relatedTarget)) {
      box.classList.remove('view-active');
    }
  }, true);
  document.addEventListener('wheel', (e) => {
    const box = viewOf(e);
    if (box && !e.ctrlKey && !e.metaKey && !box.classList.contains('view-active')) {
      e.stopPropagation();  // vtk.js never sees it: the page scrolls
    }
  }, { capture: true, passive: true });
})();
"""

# Shared links (app.logic.links): a page opened with settings in its query string hands them to
# the server once; ``url`` makes the link of the current settings, with this page's token. A
# session's page (/s/<id>/..., app.launcher) links to the launcher's root, so that whoever opens
# the link gets a session of their own with the same scene; it is given the token after "#" (never
# sent to a server). Once read, the token, the settings and the session's id leave the address
# bar (the page shows "/", whose reload opens a new session): a projected address gives nothing
# away. When the connection closes for good (the session ended), the page says so.
LINK_SCRIPT = """
(() => {
  const query = new URLSearchParams(window.location.search);
  const hash = new URLSearchParams(window.location.hash.replace(/^#/, ''));
  const token = hash.get('token') || query.get('token');
  const root = window.location.pathname.replace(/^\\/s\\/[^/]+\\/.*$/, '/');
  window.trame.utils.lmapdLink = {
    url(settings) {
      const head = token ? `token=${encodeURIComponent(token)}&` : '';
      return `${window.location.origin}${root}?${head}${settings || ''}`;
    },
    copy(settings) {
      const text = this.url(settings);
      if (navigator.clipboard) navigator.clipboard.writeText(text).catch(() => {});
      return text;
    },
    save(name, pending, type) {  // a download, unless the server refused it (null, with a message)
      Promise.resolve(pending).then((data) => {
        if (data !== null && data !== undefined) window.trame.utils.download(name, data, type);
      });
    },
  };
  query.delete('token');
  const given = Object.fromEntries(query);
  if (Object.keys(given).length) window.trame.trigger('open_link', [given]);
  window.history.replaceState(null, document.title, root);
  const client = window.trame.state && window.trame.state.client;
  if (client && client.onConnectionClose) {
    client.onConnectionClose(() => {
      if (document.querySelector('.session-ended')) return;
      const note = document.createElement('div');
      note.className = 'session-ended';
      note.setAttribute('role', 'alert');
      note.textContent = 'Session ended: reload for a new one.';
      note.style.cssText = 'position:fixed;top:0;left:0;right:0;z-index:10000;padding:12px;'
        + 'background:#b71c1c;color:#fff;font:600 16px sans-serif;text-align:center';
      document.body.appendChild(note);
    });
  }
})();
"""

CSS = """
html { overflow-y: auto; }
.controls .control { margin-bottom: 2px; }
.controls .control-label { color: #424242; margin-top: 6px; }
.controls .v-slider.v-input--horizontal { margin-inline: 4px 0; }
.controls .v-field__input { padding-inline: 8px 4px; min-height: 32px; padding-top: 4px;
  padding-bottom: 4px; font-size: 0.85rem; }
.section-title { color: #1565c0; margin-top: 10px; line-height: 1.6; font-weight: 600; }
.view-card { height: 100%; display: flex; flex-direction: column; }
.card-title { font-size: 0.98rem !important; padding: 6px 12px 2px 16px !important; }
.hint { color: #616161; }
.vtk-box { position: relative; flex: 1 1 auto; min-height: 240px; height: clamp(240px, 38vh, 560px);
  margin: 4px 8px 8px 8px; border-radius: 4px; overflow: hidden; }
.overlay { position: absolute; pointer-events: none; color: #eceff1; font-size: 12px;
  background: rgba(20, 22, 28, 0.72); border-radius: 4px; padding: 6px 8px; line-height: 1.45; }
.legend-overlay { left: 8px; top: 8px; }
.colorbar-overlay { left: 8px; bottom: 8px; min-width: 210px; }
.legend-row { display: flex; align-items: center; gap: 6px; }
.legend-head { color: #b0bec5; font-size: 11px; }
.legend-count { margin-left: auto; padding-left: 10px; color: #b0bec5;
  font-variant-numeric: tabular-nums; }
.swatch { display: inline-block; width: 12px; height: 12px; border-radius: 2px;
  border: 1px solid rgba(255,255,255,0.35); flex: none; }
.swatch-line { height: 2px; border: none; background: #ff6b40; }
.swatch-target { background: #4fc3f7; }
.swatch-outlier { background: #ff1744; }
.swatch-pinned { background: rgba(207, 216, 220, 0.5); }
.credit-overlay { position: absolute; right: 8px; bottom: 6px; color: #cfd8dc; font-size: 11px;
  pointer-events: none; text-shadow: 0 0 3px #000; }
.colorbar-title { font-size: 12px; }
.colorbar-bar { height: 10px; border-radius: 2px; margin: 2px 0; }
.colorbar-labels { display: flex; justify-content: space-between; font-size: 11px;
  font-variant-numeric: tabular-nums; }
.array-box { position: relative; width: min(100% - 16px, 33vh); aspect-ratio: 1 / 1;
  margin: 4px auto 6px auto; background: #1e1e24; overflow: hidden; }
.array-box:focus-visible { outline: 3px solid #ffb300; outline-offset: 2px; }
.array-zoom { position: absolute; left: 0; top: 0; width: 100%; height: 100%; }
.image-kind { flex-wrap: wrap; height: auto !important; max-width: 100%; }
.image-kind .v-btn { min-height: 22px; }
.pixel-readout { min-height: 1.4em; font-variant-numeric: tabular-nums; }
.array-image { width: 100%; height: 100%; display: block; image-rendering: pixelated;
  cursor: crosshair; user-select: none; }
.pixel-marker { position: absolute; width: 14px; height: 14px; border: 2px solid;
  border-radius: 50%; transform: translate(-50%, -50%); pointer-events: none;
  box-shadow: 0 0 0 1px rgba(255,255,255,0.85); }
.chart-box { position: relative; margin: 0 8px 8px 8px; }
.waveform-box { height: clamp(280px, 37vh, 520px); }
.snr-box { height: 120px; }
.design-front-box { height: 280px; }
.wrap-toggle { flex-wrap: wrap; height: auto !important; max-width: 100%; }
.wrap-toggle .v-btn { min-height: 26px; }
.chart-box .js-plotly-plot, .chart-box .plot-container { height: 100%; }
.stats-table td { height: 22px !important; font-size: 0.78rem; padding: 0 6px !important; }
.stat-value { font-variant-numeric: tabular-nums; font-weight: 500; text-align: right; }
.subtitle { color: #616161; }
.app-title { font-weight: 600; letter-spacing: 0.02em; }
.footer-text { font-size: 12px; color: #616161; }
.stats-grid { display: grid; grid-template-columns: repeat(auto-fit, minmax(220px, 1fr));
  column-gap: 8px; padding: 0 8px; }
.image-kind { flex-wrap: wrap; height: auto !important; }
@media (max-width: 600px) {
  .v-app-bar .v-toolbar-title { flex: 0 0 auto; }
  .overlay { font-size: 10px; padding: 4px 6px; }
  .colorbar-overlay { min-width: 150px; }
  .legend-count { padding-left: 4px; }
}
/* the 3D views leave the page's scroll alone (VIEW_SCROLL_SCRIPT): until a view is clicked or
   tapped, a finger swipe over it scrolls the page (vtk.js sets touch-action: none inline) */
.vtk-box:not(.view-active) div, .vtk-box:not(.view-active) canvas {
  touch-action: pan-y !important; }
.vtk-box.view-active { box-shadow: 0 0 0 2px #64b5f6; }
.busy-bar { position: absolute; left: 0; right: 0; bottom: 0; height: 3px; background: #ffd54f; }
"""


def app_bar() -> None:
    with v3.VAppBar(density="compact", color="#0d47a1", elevation=2):
        v3.VAppBarNavIcon(
            click="main_drawer = !main_drawer",
            color="white",
            **html_attributes(aria_label="Show or hide the controls"),
        )
        with v3.VToolbarTitle(classes="text-white"):
            html.Span("lmapd-sim", classes="app-title")
            html.Span(
                " · live LM-APD flash-lidar imaging of {{ target_name }}",
                classes="text-body-2 d-none d-md-inline",
            )
        v3.VSpacer()
        glossary.glossary_button()
        v3.VChip(
            "{{ n_points.toLocaleString() }} points",
            size="small",
            color="white",
            variant="outlined",
            classes="mr-2 point-count",
        )
        with v3.VChip(  # which frame the views show: the quick preview or the chosen preset's
            v_show="frame_label",
            size="small",
            color=("frame_kind === 'preview' ? 'amber-lighten-3' : 'white'",),
            variant=("frame_kind === 'preview' ? 'flat' : 'outlined'",),
            classes="mr-2 frame-kind",
            title="Preview: one ray per pixel, no refinement, shown while the chosen fidelity "
            "preset's frame is computed",
        ):
            html.Span("{{ frame_label }}", classes="d-none d-sm-inline")
            html.Span(  # a phone's app bar keeps room for the title
                "{{ frame_kind === 'preview' ? 'preview' : 'preset' }}", classes="d-sm-none"
            )
        v3.VChip(
            "computing…",
            v_show="busy",
            size="small",
            color="amber-lighten-3",
            variant="flat",
            prepend_icon="mdi-timer-sand",
            classes="mr-2 busy-chip",
        )
        # a static bar, not an animated one: on a software-rendered page an endless animation
        # repaints 60 times a second and takes CPU from the simulation
        html.Div(v_show="busy", classes="busy-bar")


def messages() -> None:
    v3.VAlert(
        "{{ error_message }}",
        v_if="error_message",
        type="error",
        density="compact",
        variant="tonal",
        closable=True,
        click_close="error_message = ''",
        classes="mb-2 error-message",
        __events=[("click_close", "click:close")],
    )
    v3.VAlert(
        "{{ input_message }}",
        v_if="input_message",
        type="warning",
        density="compact",
        variant="tonal",
        closable=True,
        click_close="input_message = ''",
        classes="mb-2 input-message",
        __events=[("click_close", "click:close")],
    )


def views_grid() -> None:
    with v3.VContainer(fluid=True, classes="pa-2"):
        messages()
        lessons.lesson_card()
        design.study_card()
        with v3.VRow(dense=True):
            with v3.VCol(cols=12, lg=6):
                views3d.scene_card()
            with v3.VCol(cols=12, lg=6):
                views3d.cloud_card()
        with v3.VRow(dense=True):
            with v3.VCol(cols=12, md=5, lg=4, xl=3):
                panels.array_card()
            with v3.VCol(cols=12, md=7, lg=8, xl=5):
                panels.waveform_card()
            with v3.VCol(cols=12, xl=4):
                panels.stats_card()
        footer()


def footer() -> None:
    with v3.VFooter(border=True, classes="py-1 mt-2 flex-wrap page-footer"):
        html.Span("{{ credit }}", classes="footer-text nasa-credit")
        v3.VSpacer()
        html.Span(
            "Physics: Wang et al., Electronics 2023, 12, 2261 · built with trame and vtk.js",
            classes="footer-text",
        )


def build_layout(server) -> VAppLayout:
    """Build the page on ``server`` (state and triggers are set up by app.logic.controller)."""
    # the drawer's state is each page's own: open beside the views on a wide screen, closed on a
    # narrow one (below the md breakpoint, 960 px, it opens over the views and closes on a tap
    # outside: Vuetify's temporary drawer)
    server.state.client_only("main_drawer")
    server.state.glossary_open = False  # the glossary dialog, and the entry asked for
    server.state.glossary_term = ""
    server.state.client_only("glossary_open", "glossary_term")
    server.state.link_copied = ""  # what "Copy link" answered (app.ui.controls.share_panel)
    server.state.client_only("link_copied")
    with VAppLayout(server, full_height=True) as layout:
        client.Style(CSS)
        client.Script(FRAME_SCRIPT)  # before the watcher below: created first
        client.Script(views3d.BINARY_SCRIPT)  # before the views that read binary arrays
        client.Script(A11Y_SCRIPT)
        client.Script(LINK_SCRIPT)
        client.Script(VIEW_SCROLL_SCRIPT)
        client.Script(classroom.KEYBOARD_SCRIPT)
        client.Style(classroom.CURSOR_CSS)
        client.Style(glossary.CSS)
        glossary.glossary_dialog()
        lessons.physics_dialog()
        client.ClientStateChange(value="frame_key", change=FRAME_SHOWN, trigger_on_create=True)
        app_bar()
        with v3.VNavigationDrawer(
            v_model=("main_drawer", None), width=330, mobile_breakpoint="md", location="left"
        ):
            controls.drawer_content()
        with v3.VMain():
            views_grid()
    layout.title = "lmapd-sim"
    return layout
