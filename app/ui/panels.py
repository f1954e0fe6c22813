"""The 2D panels: the detector array image (click selects a pixel, shift-click adds), the
waveform chart of the selected pixels, and the stats (counts, SNR distribution, stage times)."""

from __future__ import annotations

from trame.widgets import html, plotly
from trame.widgets import vuetify3 as v3

from app.ui import compare
from app.ui.widgets import button_toggle, html_attributes

# (A handler that starts as an arrow function would be taken by Vue for the handler itself and
# evaluated when drawn: those below that run one start with ``void``.)
# The image's zoom lives in the page (client-only state ``array_zoom``: scale s in [1, 16], the
# visible window's top-left corner x, y in fractions of the image). ZOOM(z, f, u, v): zoom by f
# about the point at fractions (u, v) of the box, which stays put.
ZOOM = (
    "((z, f, u, v) => { const s = Math.min(16, Math.max(1, z.s * f)), m = 1 - 1 / s; "
    "return { s: s, x: Math.min(m, Math.max(0, z.x + u / z.s - u / s)), "
    "y: Math.min(m, Math.max(0, z.y + v / z.s - v / s)) }; })"
)
# The (row, col) under the pointer on the image, which is laid out at its zoomed size: its place
# on the image alone gives it (offsetX, offsetY: relative to the image, in whole CSS pixels as
# Chromium gives them, so the pixel whose centre was clicked even where a pixel is 1.1 CSS pixels).
PIXEL_AT = (
    "[Math.floor($event.offsetY / $event.currentTarget.clientHeight * array_image.pixels), "
    "Math.floor($event.offsetX / $event.currentTarget.clientWidth * array_image.pixels)]"
)
# A click selects the pixel (shift-click adds), unless it ended a drag.
PIXEL_CLICK = (
    "$event.currentTarget.closest('.array-box').dataset.dragged !== '1' && "
    f"trigger('pixel_click', {PIXEL_AT}.concat([$event.shiftKey]))"
)
# The pointer's pixel goes to the server for its readout when it changes, at most every 50 ms
# (and once more 60 ms after the last move, so the readout ends on the pixel under the pointer).
PIXEL_HOVER = (
    f"void ((p, el, w) => {{ const send = () => {{ if (el.dataset.hover !== p.join()) {{ "
    "el.dataset.hover = p.join(); el.dataset.t = Date.now(); trigger('pixel_hover', p); } }; "
    "w.clearTimeout(+el.dataset.timer); "
    "if (Date.now() - (+el.dataset.t || 0) > 50) send(); "
    "else el.dataset.timer = w.setTimeout(send, 60); })"
    f"({PIXEL_AT}, $event.currentTarget, $event.view)"
)
HOVER_END = "$event.currentTarget.dataset.hover = ''; trigger('pixel_hover', [])"
# The wheel zooms about the pointer with Ctrl (or Cmd) held, or once the image was clicked
# (until the pointer leaves it); otherwise it scrolls the page, as over the 3D views.
WHEEL = (
    "array_zoom = ((e, el, z) => { "
    "if (!(e.ctrlKey || e.metaKey || el.dataset.active === '1')) return z; "
    "e.preventDefault(); const r = el.getBoundingClientRect(); "
    f"return {ZOOM}(z, e.deltaY < 0 ? 1.25 : 0.8, "
    "(e.clientX - r.left) / r.width, (e.clientY - r.top) / r.height); })"
    "($event, $event.currentTarget, array_zoom)"
)
# Drag pans (when zoomed); a drag's last mouse-up is not a click.
DRAG_START = (
    "$event.currentTarget.dataset.drag = [$event.clientX, $event.clientY, array_zoom.x, "
    "array_zoom.y].join(); $event.currentTarget.dataset.dragged = '0'; "
    "$event.currentTarget.dataset.active = '1'"
)
DRAG = (
    "void ((e, el, z) => { if (!(e.buttons & 1) || !el.dataset.drag || z.s <= 1) return; "
    "const d = el.dataset.drag.split(',').map(Number), r = el.getBoundingClientRect(), "
    "m = 1 - 1 / z.s, dx = e.clientX - d[0], dy = e.clientY - d[1]; "
    "if (Math.abs(dx) + Math.abs(dy) > 4) el.dataset.dragged = '1'; "
    "array_zoom = { s: z.s, x: Math.min(m, Math.max(0, d[2] - dx / r.width / z.s)), "
    "y: Math.min(m, Math.max(0, d[3] - dy / r.height / z.s)) }; })"
    "($event, $event.currentTarget, array_zoom)"
)
DRAG_END = "$event.currentTarget.dataset.drag = ''"
LEAVE = "$event.currentTarget.dataset.drag = ''; $event.currentTarget.dataset.active = ''"
# Keys on the focused image (app/static/keyboard.js): arrows move a cursor pixel (the
# zoomed view follows it), Enter selects it, Shift+Enter adds it; Ctrl + arrows pan, + and - zoom
# about the centre, 0 resets.
KEYS = (
    "void ((r) => { array_zoom = r[0]; array_cursor = r[1]; })(trame.utils.lmapdArray.key("
    "$event, array_zoom, array_cursor, array_image.pixels, selected_pixels))"
)
CURSOR_STYLE = (
    "{ left: ((array_cursor[1] + 0.5) / array_image.pixels * 100) + '%', "
    "top: ((array_cursor[0] + 0.5) / array_image.pixels * 100) + '%', "
    "width: (100 / array_image.pixels) + '%', height: (100 / array_image.pixels) + '%' }"
)
# The zoomed image is laid out at its zoomed size (not scaled by a CSS transform, which would
# scale the image as drawn at the box's size: its pixel edges rounded there, up to half a pixel
# off at high zoom), so each pixel lies where a click finds it.
ZOOM_STYLE = (
    "{ width: (100 * array_zoom.s) + '%', height: (100 * array_zoom.s) + '%', "
    "left: (-100 * array_zoom.s * array_zoom.x) + '%', "
    "top: (-100 * array_zoom.s * array_zoom.y) + '%' }",
)
PEAK_STYLE = (
    "{ left: ((p[1] + 0.5) / array_image.pixels * 100) + '%', "
    "top: ((p[0] + 0.5) / array_image.pixels * 100) + '%' }"
)
# what the dark pixels of each image mean (a pixel whose echo was not detected still has a peak
# power, so it is coloured in that image)
DARK_MEANS = (
    "({ range: 'dark: no point', peak_power: 'dark: no echo; echoes not detected are coloured "
    "too', background: 'dark: no background light', multi_peak: 'dark: no echo; rings mark the "
    "pixels with two or more peaks' })[image_kind] || ''"
)
MARKER_STYLE = (
    "{ left: ((p[1] + 0.5) / array_image.pixels * 100) + '%', "
    "top: ((p[0] + 0.5) / array_image.pixels * 100) + '%', "
    "borderColor: selection_colors[i % selection_colors.length] }"
)


def _zoom_button(icon: str, label: str, action: str) -> None:
    v3.VBtn(
        icon=icon,
        size="x-small",
        variant="text",
        title=label,
        click=action,
        **html_attributes(aria_label=label),
    )


def array_card() -> None:
    with v3.VCard(classes="view-card array-card", elevation=1):
        with v3.VCardTitle(classes="card-title d-flex align-center flex-wrap"):
            html.Span("Detector array {{ array_image.pixels }} × {{ array_image.pixels }}")
            v3.VSpacer()
            button_toggle(
                "image_kind",
                [
                    ("Range", "range", ""),
                    ("Peak power", "peak_power", ""),
                    ("Background", "background", "image-background"),
                    ("Multi-peak", "multi_peak", "image-multi-peak"),
                ],
                size="x-small",
                classes="image-kind",
                label="Array image shows",
            )
        with html.Div(classes="d-flex align-center px-4"):
            html.Div(
                "Click a pixel to see its echo; shift-click adds more (keys: arrows move a "
                "cursor, Enter selects, Shift+Enter adds). Ctrl + wheel (or click, then wheel), "
                "drag, Ctrl + arrows, + / − zoom and pan.",
                classes="hint text-caption",
            )
            v3.VSpacer()
            _zoom_button(
                "mdi-magnify-plus-outline",
                "Zoom in",
                f"array_zoom = {ZOOM}(array_zoom, 1.5, 0.5, 0.5)",
            )
            _zoom_button(
                "mdi-magnify-minus-outline",
                "Zoom out",
                f"array_zoom = {ZOOM}(array_zoom, 1 / 1.5, 0.5, 0.5)",
            )
            _zoom_button(
                "mdi-fit-to-screen-outline", "Reset zoom", "array_zoom = { s: 1, x: 0, y: 0 }"
            )
        with html.Div(
            classes="array-box",
            tabindex="0",
            wheel=WHEEL,
            __events=["wheel"],  # not among trame's known DOM events
            mousedown=DRAG_START,
            mousemove=DRAG,
            mouseup=DRAG_END,
            mouseleave=LEAVE,
            keydown=KEYS,
            **html_attributes(
                role="group",
                aria_label="Detector array image: arrow keys move the cursor pixel, Enter "
                "selects it, Shift+Enter adds it; Ctrl+arrows pan, plus and minus zoom, 0 resets",
            ),
        ):
            with html.Div(classes="array-zoom", style=ZOOM_STYLE):
                html.Img(
                    src=("trame.utils.lmapdBin.imageUrl(array_image)",),
                    v_show="array_image.png",
                    classes="array-image",
                    draggable="false",
                    alt=(ARRAY_DESCRIPTION,),
                    click=PIXEL_CLICK,
                    mousemove=PIXEL_HOVER,
                    mouseleave=HOVER_END,
                )
                html.Div(  # rings on the multi-peak pixels: visible at any zoom (at most 300)
                    v_for="(p, i) in (array_image.multi_peak || []).slice(0, 300)",
                    key="'m' + i",
                    classes="peak-marker",
                    style=(PEAK_STYLE,),
                )
                html.Div(
                    v_if="array_cursor && array_cursor[0] < array_image.pixels",
                    classes="array-cursor",
                    style=(CURSOR_STYLE,),
                )
                html.Div(
                    v_for="(p, i) in selected_pixels",
                    key="i",
                    classes="pixel-marker",
                    style=(MARKER_STYLE,),
                )
        html.Div(
            "{{ pixel_readout ? pixel_readout.text : "
            "'Point at a pixel for its range, SNR and echo peaks' }}",
            classes="pixel-readout text-caption px-4",
            **html_attributes(aria_live="polite"),
        )
        with html.Div(v_if="array_image.colorbar", classes="colorbar px-4 pb-2"):
            html.Div(
                f"{{{{ array_image.colorbar.title }}}} ({{{{ {DARK_MEANS} }}}})",
                classes="colorbar-title",
            )
            html.Div(
                classes="colorbar-bar", style=("{ background: array_image.colorbar.gradient }",)
            )
            with html.Div(classes="colorbar-labels"):
                html.Span("{{ array_image.colorbar.lo }}")
                html.Span("{{ array_image.colorbar.hi }}")


# The waveform chart's measuring cursor (app/static/cursor.js): a click on a trace places cursor A,
# the next B; the readout (the page's own state, never sent) gives their times, ranges and
# difference.
CURSOR_CLICK = "wave_cursor = trame.utils.lmapdCursor.click($event)"


def waveform_card() -> None:
    with v3.VCard(
        classes="view-card waveform-card",
        elevation=1,
        **html_attributes(aria_describedby="waveform-description"),
    ):
        html.P(  # the chart's traces in words: each selected pixel's echo and what became of it
            "{{ view_text.waveform_title + ': ' + (((waveforms || {}).data || []).filter((t) =>"
            " t.showlegend !== false && t.name && t.name.startsWith('(')).map((t) => t.name)"
            ".join('; ') || 'no pixel selected') + '.' }}",
            id="waveform-description",
            classes="sr-only",
        )
        with v3.VCardTitle(classes="card-title"):
            html.Span("{{ view_text.waveform_title }}")
        html.Div("{{ view_text.waveform_caption }}", classes="hint text-caption px-4")
        with html.Div(classes="chart-box waveform-box"):
            plotly.Figure(
                state_variable_name="waveforms",
                display_logo=False,
                responsive=True,
                mode_bar_buttons_to_remove=(
                    "['select2d', 'lasso2d', 'autoScale2d', 'toggleSpikelines']",
                ),
                click=CURSOR_CLICK,
                after_plot="trame.utils.lmapdCursor.redraw()",
            )
        with html.Div(classes="d-flex align-center px-4 wave-cursor"):
            html.Span(
                "{{ wave_cursor || 'Click a trace to place a measuring cursor (A, then B)' }}",
                classes="text-caption hint wave-cursor-text",
            )
            v3.VSpacer()
            v3.VBtn(
                "Clear",
                v_if="wave_cursor",
                size="x-small",
                variant="text",
                click="wave_cursor = trame.utils.lmapdCursor.clear()",
                classes="wave-cursor-clear",
            )


def _table(
    rows: str, key: str, label: str, value: str, value_class: str, info: bool = False
) -> None:
    """A table of ``rows``; ``info``: a row with a glossary term (``row.term``) has an info
    button that opens the glossary there."""
    with v3.VTable(density="compact", classes="stats-table"):
        with html.Tbody():
            with html.Tr(v_for=f"row in {rows}", key=key):
                with html.Td():
                    html.Span(label)
                    if info:
                        v3.VBtn(
                            v_if="row.term",
                            icon="mdi-information-outline",
                            size="x-small",
                            density="compact",
                            variant="text",
                            color="primary",
                            title=("'What is ' + row.term + '? (the glossary)'",),
                            click="glossary_term = row.term; glossary_open = true",
                            classes="info-button stats-info ml-1",
                            **html_attributes(aria_label=("'What is ' + row.term + '?'",)),
                        )
                html.Td(value, classes=value_class)


def quality_block() -> None:
    """The frame scored against the target's true mesh, on demand (app.logic: score_quality)."""
    with html.Div(classes="px-2 pt-1 quality-block"):
        v3.VBtn(
            "Score this cloud against the true target",
            prepend_icon="mdi-target",
            size="small",
            variant="tonal",
            color="primary",
            loading=("quality_busy",),
            click="trigger('score_quality')",
            classes="score-quality",
            v_if="!quality_rows.length",
        )
        with html.Div(v_if="quality_rows.length"):
            html.Div(
                "The cloud against the mesh it came from (docs/physics.md#imaging-quality)",
                classes="subtitle text-caption px-2",
            )
            _table("quality_rows", "row.label", "{{ row.label }}", "{{ row.value }}", "stat-value")


# What a screen reader reads of the stats card and the array image, from each frame's figures
STATS_KEY_ROWS = (
    "Points",
    "Target points",
    "Outliers (false alarms)",
    "Dropped pixels (missed)",
    "Pixels with an echo (lit)",
)
STATS_DESCRIPTION = (
    "'Statistics of this flash: ' + (stats || []).filter((r) => "
    + repr(list(STATS_KEY_ROWS)).replace('"', "'")
    + ".includes(r.label)).map((r) => r.label + ' ' + r.value).join(', ') + '.'"
)
ARRAY_DESCRIPTION = (
    "'Detector array image, ' + array_image.pixels + ' by ' + array_image.pixels + ' pixels, "
    "showing ' + ({ range: 'the range', peak_power: 'the peak power', background: 'the "
    "background light', multi_peak: 'the pixels with two peaks' })[image_kind] + ', with ' + "
    "n_points.toLocaleString() + ' points; selected: ' + (selected_pixels.length ? "
    "selected_pixels.map((p) => 'row ' + p[0] + ' column ' + p[1]).join(', ') : 'none') + '.'"
)


def stats_card() -> None:
    with v3.VCard(
        classes="view-card stats-card",
        elevation=1,
        **html_attributes(aria_describedby="stats-description"),
    ):
        html.P(
            (f"{{{{ {STATS_DESCRIPTION} }}}}"),
            id="stats-description",
            classes="sr-only",
            **html_attributes(aria_live="polite"),
        )
        with v3.VCardTitle(classes="card-title d-flex align-center flex-wrap ga-2"):
            html.Span("Statistics of this flash")
            v3.VSpacer()
            compare.pin_button()
        compare.compare_table()
        with html.Div(classes="stats-grid"):  # side by side where the card is wide enough
            with html.Div():
                _table(
                    "stats", "row.label", "{{ row.label }}", "{{ row.value }}", "stat-value", True
                )
            with html.Div():
                html.Div("Time per stage (ms)", classes="subtitle text-caption px-2")
                _table(
                    "stages",
                    "row.stage",
                    "{{ row.stage }}",
                    "{{ row.ms }}",
                    ("['stat-value', row.cached ? 'text-disabled' : '']",),
                )
        quality_block()
        html.Div("{{ view_text.snr_caption }}", classes="subtitle text-caption px-4 pt-1")
        with html.Div(classes="chart-box snr-box"):
            plotly.Figure(
                state_variable_name="snr_hist",
                display_mode_bar=False,
                responsive=True,
            )
