"""The "Attitudes" card (app.logic.attitudes): a button that maps every attitude of the scene,
a chooser of the metric, the equal-area map (app.payloads.attitudes; a click on a cell moves
the pose sliders there) and what the map is."""

from __future__ import annotations

from trame.widgets import html, plotly
from trame.widgets import vuetify3 as v3

from app.ui.widgets import html_attributes

# a click on a cell: its (pitch, azimuth) to the server (a click off the cells sends nothing)
CELL_CLICK = (
    "$event && $event.points && $event.points[0] && $event.points[0].customdata && "
    "trigger('attitudes_click', [$event.points[0].customdata])"
)
CAPTION = (
    "Every view direction of the target, computed at a light preset (at most 32 × 32 pixels, "
    "the interactive fidelity, the scene's other settings). Equal-area map: the height is the "
    "sine of the pitch, so each cell's area is its solid angle. Grey: the target is not seen. "
    "Ring: the current attitude. Click a cell to move the pitch and azimuth there."
)


def attitudes_card() -> None:
    with v3.VCard(classes="view-card attitudes-card", elevation=1):
        with v3.VCardTitle(classes="card-title d-flex align-center flex-wrap ga-2"):
            html.Span("Attitudes")
            v3.VSpacer()
            v3.VSelect(
                v_model=("attitudes_metric",),
                items=("attitudes_metrics",),
                label="Map shows",
                density="compact",
                variant="outlined",
                hide_details=True,
                style="max-width: 180px",
                classes="attitudes-metric",
            )
            v3.VBtn(
                "Map every attitude",
                prepend_icon="mdi-earth",
                size="small",
                variant="tonal",
                color="primary",
                loading=("attitudes_busy",),
                disabled=("mode === 'flyaround'",),
                click="trigger('attitudes_compute')",
                classes="attitudes-compute",
                **html_attributes(aria_label="Map the imaging quality over every attitude"),
            )
            v3.VBtn(
                "Stop",
                v_if="attitudes_busy",
                size="small",
                variant="text",
                click="trigger('attitudes_stop')",
                classes="attitudes-stop",
                **html_attributes(aria_label="Stop the attitude map"),
            )
        html.Div(CAPTION, classes="hint text-caption px-4")
        v3.VAlert(
            "{{ attitudes_message }}",
            v_if="attitudes_message",
            type="warning",
            density="compact",
            variant="tonal",
            closable=True,
            click_close="attitudes_message = ''",
            classes="mx-4 my-1 attitudes-message",
            __events=[("click_close", "click:close")],
        )
        html.Div(
            "{{ attitudes_status }}",
            classes="text-caption px-4 attitudes-status",
            **html_attributes(aria_live="polite"),
        )
        with html.Div(
            v_if="attitudes_map",
            classes="chart-box attitudes-box",
            **html_attributes(
                role="group",
                aria_label="Attitude map: click a cell to move the pitch and azimuth there",
            ),
        ):
            plotly.Figure(
                state_variable_name="attitudes_map",
                display_mode_bar=False,
                responsive=True,
                click=CELL_CLICK,
            )
