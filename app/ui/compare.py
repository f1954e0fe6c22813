"""Compare (app.logic.compare): the pin button and the side-by-side table of the pinned frame
and the new one, both in the stats panel; the pinned cloud is drawn by app.ui.views3d."""

from __future__ import annotations

from trame.widgets import html
from trame.widgets import vuetify3 as v3

from app.ui.widgets import html_attributes


def pin_button() -> None:
    """Pin the frame shown, or drop the pinned one."""
    v3.VBtn(
        "Pin this frame",
        v_if="!pinned",
        prepend_icon="mdi-pin-outline",
        size="x-small",
        variant="tonal",
        color="primary",
        click="trigger('pin_frame')",
        classes="pin-frame",
        **html_attributes(title="Keep this frame's figures and cloud to compare with the next"),
    )
    v3.VBtn(
        "Unpin",
        v_if="pinned",
        prepend_icon="mdi-pin-off-outline",
        size="x-small",
        variant="tonal",
        click="trigger('unpin_frame')",
        classes="unpin-frame",
        **html_attributes(aria_label="Unpin the pinned frame"),
    )


def compare_table() -> None:
    """Pinned against new: points, outliers, dropped pixels, median SNR, median range sigma."""
    with html.Div(v_if="pinned && compare_rows.length", classes="compare px-2 pb-1"):
        html.Div(
            "Pinned: {{ pinned.label }} (its cloud drawn faintly in the point-cloud view)",
            classes="text-caption hint px-2 compare-label",
        )
        with v3.VTable(density="compact", classes="stats-table compare-table"):
            with html.Thead():
                with html.Tr():
                    html.Th("")
                    html.Th("pinned", classes="stat-value")
                    html.Th("now", classes="stat-value")
                    html.Th("change", classes="stat-value")
            with html.Tbody():
                with html.Tr(v_for="row in compare_rows", key="row.label"):
                    html.Td("{{ row.label }}")
                    html.Td("{{ row.pinned }}", classes="stat-value compare-pinned")
                    html.Td("{{ row.now }}", classes="stat-value compare-now")
                    html.Td("{{ row.change }}", classes="stat-value compare-change")
