"""The page: app bar (title, busy indicator, frame info), drawer (controls), the views in a grid,
messages, and a footer with the NASA credit."""

from __future__ import annotations

from trame.ui.vuetify3 import VAppLayout
from trame.widgets import client, html
from trame.widgets import vuetify3 as v3

from app.ui import attitudes, charts, controls, design, glossary, lessons, panels, static, views3d
from app.ui.widgets import html_attributes

# After the page applied a frame, the frame-pacing helper (app/static/frame.js) waits until it is
# on screen and tells the server (trigger frame_shown). The page's scripts and styles are the files
# of app/static/ (app.ui.static).
FRAME_SHOWN = "trame.utils.lmapd && trame.utils.lmapd.frameShown($event)"


def app_bar() -> None:
    with v3.VAppBar(density="compact", color="#0d47a1", elevation=2):
        v3.VAppBarNavIcon(
            click="main_drawer = !main_drawer",
            color="white",
            **html_attributes(aria_label="Show or hide the controls"),
        )
        with v3.VToolbarTitle(classes="text-white"):
            html.Span("lmapd-sim", classes="app-title")
            html.Span(  # the full line where it fits, the target's name alone where not
                " · live LM-APD flash-lidar imaging of {{ target_name }}",
                classes="text-body-2 d-none d-xl-inline app-subtitle",
            )
            html.Span(
                " · {{ target_name }}",
                classes="text-body-2 d-none d-md-inline d-xl-none app-subtitle-short",
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
    v3.VAlert(  # a heavy frame waits for the server's memory (other tabs' frames hold it)
        "{{ memory_message }}",
        v_if="memory_message",
        type="info",
        density="compact",
        variant="tonal",
        prepend_icon="mdi-timer-sand",
        classes="mb-2 memory-message",
    )
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
    """The views: the two 3D views first; the array image, the echo waveforms and the stats
    are built with the drawer's controls, once the first frame is on screen
    (``controls.CONTROLS_READY``). A new tab's first picture is the 3D views; building the
    rest after it made that picture about 0.09 s sooner on this project's 2-core machine, and
    the whole page no later (docs/serving.md)."""
    with v3.VContainer(fluid=True, classes="pa-2"):
        messages()
        lessons.lesson_card()
        design.study_card()
        with v3.VRow(dense=True):
            with v3.VCol(cols=12, lg=6):
                views3d.scene_card()
            with v3.VCol(cols=12, lg=6):
                views3d.cloud_card()
        with v3.VRow(dense=True, v_if=controls.CONTROLS_READY):
            with v3.VCol(cols=12, md=5, lg=4, xl=3):
                panels.array_card()
            with v3.VCol(cols=12, md=7, lg=8, xl=5):
                panels.waveform_card()
            with v3.VCol(cols=12, xl=4):
                panels.stats_card()
        with v3.VRow(dense=True, v_if=controls.CONTROLS_READY):
            with v3.VCol(cols=12, lg=8, xl=6):
                attitudes.attitudes_card()
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
    server.state.wave_cursor = ""  # the waveform chart's cursor readout (app.ui.panels)
    server.state.client_only("wave_cursor")
    with VAppLayout(server, full_height=True) as layout:
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
    charts.defer_plotly(server)  # plotly's bundle after the first frame (app/static/charts.js)
    static.enable(server)  # last: the page's styles after the widget libraries' ones
    return layout
