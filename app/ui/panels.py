"""The 2D panels: the detector array image (click selects a pixel, shift-click adds), the
waveform chart of the selected pixels, and the stats (counts, SNR distribution, stage times)."""

from __future__ import annotations

from trame.widgets import html, plotly
from trame.widgets import vuetify3 as v3

from app.ui import compare
from app.ui.widgets import button_toggle

# Pixel (row, col) under the mouse from the click position on the n x n image.
PIXEL_CLICK = (
    "trigger('pixel_click', ["
    "Math.floor($event.offsetY / $event.currentTarget.clientHeight * array_image.pixels), "
    "Math.floor($event.offsetX / $event.currentTarget.clientWidth * array_image.pixels), "
    "$event.shiftKey])"
)
MARKER_STYLE = (
    "{ left: ((p[1] + 0.5) / array_image.pixels * 100) + '%', "
    "top: ((p[0] + 0.5) / array_image.pixels * 100) + '%', "
    "borderColor: selection_colors[i % selection_colors.length] }"
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
                ],
                size="x-small",
                classes="image-kind",
                label="Array image shows",
            )
        html.Div(
            "Click a pixel to see its echo; shift-click adds more.",
            classes="hint text-caption px-4",
        )
        with html.Div(classes="array-box"):
            html.Img(
                src=("array_image.src",),
                v_show="array_image.src",
                classes="array-image",
                draggable="false",
                alt="detector array image",
                click=PIXEL_CLICK,
            )
            html.Div(
                v_for="(p, i) in selected_pixels",
                key="i",
                classes="pixel-marker",
                style=(MARKER_STYLE,),
            )
        with html.Div(v_if="array_image.colorbar", classes="colorbar px-4 pb-2"):
            html.Div(
                "{{ array_image.colorbar.title }} (dark: no echo / not detected)",
                classes="colorbar-title",
            )
            html.Div(
                classes="colorbar-bar", style=("{ background: array_image.colorbar.gradient }",)
            )
            with html.Div(classes="colorbar-labels"):
                html.Span("{{ array_image.colorbar.lo }}")
                html.Span("{{ array_image.colorbar.hi }}")


def waveform_card() -> None:
    with v3.VCard(classes="view-card waveform-card", elevation=1):
        with v3.VCardTitle(classes="card-title"):
            html.Span("Echo waveforms of the selected pixels")
        html.Div(
            "solid: received (band-limited) · dotted: unfiltered · dashed: emitted pulse "
            "delayed by 2R/c · ◆ half-maximum time · vertical line: detected range · "
            "dash-dot: threshold",
            classes="hint text-caption px-4",
        )
        with html.Div(classes="chart-box waveform-box"):
            plotly.Figure(
                state_variable_name="waveforms",
                display_logo=False,
                responsive=True,
                mode_bar_buttons_to_remove=(
                    "['select2d', 'lasso2d', 'autoScale2d', 'toggleSpikelines']",
                ),
            )


def _table(rows: str, key: str, label: str, value: str, value_class: str) -> None:
    with v3.VTable(density="compact", classes="stats-table"):
        with html.Tbody():
            with html.Tr(v_for=f"row in {rows}", key=key):
                html.Td(label)
                html.Td(value, classes=value_class)


def stats_card() -> None:
    with v3.VCard(classes="view-card stats-card", elevation=1):
        with v3.VCardTitle(classes="card-title d-flex align-center flex-wrap ga-2"):
            html.Span("Statistics of this flash")
            v3.VSpacer()
            compare.pin_button()
        compare.compare_table()
        with html.Div(classes="stats-grid"):  # side by side where the card is wide enough
            with html.Div():
                _table("stats", "row.label", "{{ row.label }}", "{{ row.value }}", "stat-value")
            with html.Div():
                html.Div("Time per stage (ms)", classes="subtitle text-caption px-2")
                _table(
                    "stages",
                    "row.stage",
                    "{{ row.stage }}",
                    "{{ row.ms }}",
                    ("['stat-value', row.cached ? 'text-disabled' : '']",),
                )
        html.Div("SNR of the pixels with an echo", classes="subtitle text-caption px-4 pt-1")
        with html.Div(classes="chart-box snr-box"):
            plotly.Figure(
                state_variable_name="snr_hist",
                display_mode_bar=False,
                responsive=True,
            )
