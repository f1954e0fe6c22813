"""The Design page: the drawer's study chooser (shown when the app has a ``--studies`` folder)
and, above the views, the chosen study's front and its designs, each with a button that opens it
in the views (app.logic.studies)."""

from __future__ import annotations

from trame.widgets import html, plotly
from trame.widgets import vuetify3 as v3


def study_chooser() -> None:
    """In the drawer: the studies of the ``--studies`` folder."""
    with v3.VExpansionPanels(
        variant="accordion", classes="mt-2 design-panel", v_if="design_studies.length"
    ):
        with v3.VExpansionPanel():
            v3.VExpansionPanelTitle("Design studies", classes="text-body-2")
            with v3.VExpansionPanelText():
                v3.VSelect(
                    label="Study",
                    v_model=("design_study", None),
                    items=("design_studies",),
                    clearable=True,
                    density="compact",
                    variant="outlined",
                    hide_details=True,
                    classes="design-select",
                    aria_label="Design study",
                )
                html.Div(
                    "A finished lmapd design study: its costs and front appear above the views; "
                    "Open shows a design at its least favourable envelope point.",
                    classes="text-caption hint mt-1",
                )


def study_card() -> None:
    """Above the views: the chosen study's front and its front designs."""
    with v3.VCard(classes="view-card design-card mb-2", elevation=1, v_if="design_study"):
        with v3.VCardTitle(classes="card-title d-flex align-center"):
            html.Span("Design study: {{ design_study }}")
            v3.VSpacer()
            v3.VBtn(
                icon="mdi-close",
                size="small",
                variant="text",
                click="design_study = null",
                aria_label="Close the design study",
            )
        html.Div("{{ design_message }}", classes="text-body-2 px-4 design-message")
        with v3.VRow(dense=True, classes="px-2"):
            with v3.VCol(cols=12, md=6):
                with html.Div(classes="chart-box design-front-box", v_if="design_front"):
                    plotly.Figure(
                        state_variable_name="design_front",
                        display_logo=False,
                        responsive=True,
                        mode_bar_buttons_to_remove=("['select2d', 'lasso2d', 'autoScale2d']",),
                    )
            with v3.VCol(cols=12, md=6):
                with v3.VList(density="compact", classes="design-rows"):
                    with v3.VListItem(v_for="row in design_rows", key="row.number"):
                        with html.Div(classes="d-flex align-center ga-2"):
                            html.Strong("Design {{ row.number }}")
                            html.Span("{{ row.confirmed }}", classes="text-caption")
                            v3.VSpacer()
                            v3.VBtn(
                                "Open",
                                size="small",
                                variant="tonal",
                                color="primary",
                                click="trigger('open_design', [row.number])",
                                aria_label=("'Open design ' + row.number",),
                                classes="open-design",
                            )
                        html.Div("{{ row.params }}", classes="text-caption")
                        html.Div("cost: {{ row.costs }}", classes="text-caption")
                        html.Div(
                            "{{ req }}",
                            v_for="req in row.requirements",
                            classes="text-caption text-medium-emphasis",
                        )
                        html.Div(
                            "binding: {{ row.binding }}; least favourable point "
                            "{{ row.point }} ({{ row.point_text }})",
                            classes="text-caption",
                        )
