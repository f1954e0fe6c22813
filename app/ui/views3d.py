"""The two 3D views, rendered client-side by vtk.js (no server-side OpenGL): the scene (target mesh
coloured by material where seen, grey where hidden, the field-of-view frustum, arrows towards the
Sun and the Earth when there is a Sun, a legend; "Show lit side" then colours the facets that face
the Sun and those that face the Earth instead of the materials) and the point cloud (coloured by
range, SNR or outlier flag; outliers always red and larger).

Data arrive as binary typed arrays in the trame state (``app/static/binary.js`` makes vtk.js's typed
arrays of them: ``trame.utils.lmapdBin``). The whole mesh is sent once and drawn grey; the facets
seen are drawn over it in their material colours (a small mesh of their own: a few thousand facets,
their corners and colours), sent only when the set of facets seen changes. The lit side is the
whole mesh again, with the points the page holds and one colour a facet, which the page makes of
two bits a facet (``app/static/lit.js``: ``trame.utils.lmapdLit``). Each view's camera reset
(the button, or the 'r' key) goes to the home camera held in the state.
"""

from __future__ import annotations

from trame.widgets import html
from trame.widgets import vtk as vtkw
from trame.widgets import vuetify3 as v3

from app.payloads import encode
from app.payloads.scene3d import EARTH_COLOR, SUN_COLOR
from app.payloads.style import HIDDEN_COLOR
from app.payloads.track import ESTIMATE_COLOR, TRUE_COLOR
from app.ui.widgets import html_attributes

BACKGROUND = "[0.102, 0.110, 0.137]"  # #1a1c23
BACKGROUND_RGB = (26, 28, 35)
HIDDEN_RGB = [round(c / 255, 3) for c in encode.rgb_of(HIDDEN_COLOR)]
SUN_RGB, EARTH_RGB, TRUE_RGB, ESTIMATE_RGB = (
    [round(c / 255, 3) for c in encode.rgb_of(x)]
    for x in (SUN_COLOR, EARTH_COLOR, TRUE_COLOR, ESTIMATE_COLOR)
)


def _bin(key: str) -> str:
    """The template expression of state ``key`` with its binary arrays as typed arrays."""
    return f"trame.utils.lmapdBin.bin({key})"


def _view(ref: str, camera: str = "home_camera"):
    """A vtk.js view whose camera resets go to the state's ``camera``."""
    return vtkw.VtkView(
        ref=ref,
        background=(BACKGROUND,),
        reset_camera=f"trame.utils.lmapd.setCamera('{ref}', {camera})",
        __events=[("reset_camera", "resetCamera")],
    )


def _reset_button(ref: str) -> None:
    v3.VBtn(
        icon="mdi-camera-retake-outline",
        size="x-small",
        variant="text",
        title="Reset the camera",
        click=f"trame.refs['{ref}'].resetCamera()",
    )


def _card_title(text: str, ref: str) -> None:
    with v3.VCardTitle(classes="card-title d-flex align-center"):
        html.Span(text)
        v3.VSpacer()
        _reset_button(ref)


# the lit side is drawn (instead of the grey target and the seen facets' materials): the page's
# toggle is on and the frame has a Sun (and the lit side is of the mesh the page holds)
LIT_SHOWN = "trame.utils.lmapdLit.shown(show_lit_side, lit_side, target_polys)"


def _lit_switch() -> None:
    """The scene's "Show lit side" switch, there only with a Sun (``lit_side`` set). The toggle
    is each page's own (client-only state: nothing goes to the server)."""
    v3.VSwitch(
        v_if=("lit_side", None),
        v_model=("show_lit_side", False),
        label="Show lit side",
        density="compact",
        hide_details=True,
        color="amber",
        classes="lit-switch flex-grow-0 mr-2",
        style="white-space: nowrap",  # on a phone the switch goes below the title, its label whole
        title="Colour the facets that face the Sun and those that face the Earth",
    )


def scene_card() -> None:
    """Target mesh, frustum, material legend, the lit side and the model credit."""
    with v3.VCard(
        classes="view-card scene-card",
        elevation=1,
        **html_attributes(aria_describedby="scene-description"),
    ) as card:
        card.server.state.client_only("show_lit_side")
        html.P(  # what a screen reader reads of the view, from each frame's figures
            "{{ 'The 3D scene: ' + target_name + ' at ' + Math.round(distance_m) + ' m, pitch '"
            " + pitch_deg + '°, azimuth ' + azimuth_deg + '°, with the lidar\\'s field of view'"
            " + (footprint_text ? ' (' + footprint_text + ')' : '') + '. ' + (sun_text || '')"
            " + ' ' + (earth_text || '') }}",
            id="scene-description",
            classes="sr-only",
        )
        with v3.VCardTitle(classes="card-title d-flex align-center flex-wrap"):
            html.Span("3D scene: target and field of view")
            v3.VSpacer()
            _lit_switch()
            _reset_button("scene_view")
        with html.Div(classes="vtk-box scene-box"):
            with _view("scene_view", "scene_camera || home_camera"):
                with vtkw.VtkGeometryRepresentation(
                    id="target",
                    property=(f"{{ color: {HIDDEN_RGB}, ambient: 0.3, diffuse: 0.7 }}",),
                    actor=(f"{{ visibility: !{LIT_SHOWN} }}",),
                ):
                    vtkw.VtkPolyData(
                        "target", points=(_bin("target_points"),), polys=(_bin("target_polys"),)
                    )
                with vtkw.VtkGeometryRepresentation(
                    id="seen",
                    property=("{ ambient: 0.3, diffuse: 0.75, specular: 0.05 }",),
                    mapper=("{ colorMode: 2, scalarMode: 2 }",),  # direct RGB, per facet
                    actor=(f"{{ visibility: !!seen_facets && !{LIT_SHOWN} }}",),
                ):
                    vtkw.VtkMesh("seen_facets", state=(_bin("seen_facets"),))
                with vtkw.VtkGeometryRepresentation(  # the lit side: the whole mesh, per facet
                    id="lit",
                    property=("{ ambient: 0.35, diffuse: 0.65 }",),
                    mapper=("{ colorMode: 2, scalarMode: 2 }",),
                    actor=(f"{{ visibility: {LIT_SHOWN} }}",),
                ):
                    with vtkw.VtkPolyData(
                        "lit", points=(_bin("target_points"),), polys=(_bin("target_polys"),)
                    ):
                        with vtkw.VtkCellData():
                            vtkw.VtkDataArray(
                                registration="setScalars",
                                name="lit",
                                type="Uint8Array",
                                number_of_components=(3,),  # a number, not "3"
                                values=("trame.utils.lmapdLit.colors(lit_side)",),
                            )
                with vtkw.VtkGeometryRepresentation(
                    id="highlight",
                    property=("{ color: [1.0, 0.86, 0.1], ambient: 0.5, diffuse: 0.6 }",),
                    actor=("{ visibility: !!highlight_part }",),
                ):
                    vtkw.VtkPolyData(
                        "highlight",
                        points=(_bin("target_points"),),
                        polys=(_bin("highlight_cells"),),
                    )
                with vtkw.VtkGeometryRepresentation(
                    id="frustum",
                    property=("{ color: [1.0, 0.42, 0.25], lineWidth: 1.5, lighting: false }",),
                    actor=("{ visibility: !!frustum }",),  # no input before the first frame
                ):
                    vtkw.VtkMesh("frustum", state=(_bin("frustum"),))
                # the pose track's triads: the true one wide, the estimate thin over it (where
                # they coincide both show)
                for name, rgb, width in (("true", TRUE_RGB, 6), ("estimate", ESTIMATE_RGB, 2)):
                    with vtkw.VtkGeometryRepresentation(
                        id=f"fly_triad_{name}",
                        property=(f"{{ color: {rgb}, lineWidth: {width}, lighting: false }}",),
                        actor=(f"{{ visibility: !!fly_triad_{name} }}",),
                    ):
                        vtkw.VtkMesh(f"fly_triad_{name}", state=(_bin(f"fly_triad_{name}"),))
                for name, rgb in (("sun", SUN_RGB), ("earth", EARTH_RGB)):  # seen from the target
                    with vtkw.VtkGeometryRepresentation(
                        id=f"{name}_arrow",
                        property=(f"{{ color: {rgb}, lineWidth: 3, lighting: false }}",),
                        actor=(f"{{ visibility: !!{name}_arrow }}",),
                    ):
                        vtkw.VtkMesh(f"{name}_arrow", state=(_bin(f"{name}_arrow"),))
            _material_legend()
            html.Div("{{ credit }}", classes="credit-overlay")


def _material_legend() -> None:
    with html.Div(classes="overlay legend-overlay"):
        with html.Div(v_if=f"!{LIT_SHOWN}"):
            with html.Div(classes="legend-row legend-head"):
                html.Span("material (facets seen / all)")
            with html.Div(v_for="m in legend", key="m.name", classes="legend-row"):
                html.Span(classes="swatch", style=("{ background: m.color }",))
                html.Span("{{ m.label }}", classes="legend-label")
                html.Span(
                    "{{ m.seen.toLocaleString() }} / {{ m.total.toLocaleString() }}",
                    classes="legend-count",
                )
        with html.Div(v_else=True, classes="lit-legend"):
            with html.Div(classes="legend-row legend-head"):
                html.Span("lit side (facets, by their normals)")
            with html.Div(v_for="r in lit_side.rows", key="r.label", classes="legend-row lit-row"):
                html.Span(classes="swatch", style=("{ background: r.color }",))
                html.Span("{{ r.label }}", classes="legend-label")
                html.Span("{{ r.facets.toLocaleString() }}", classes="legend-count")
        with html.Div(v_if="highlight_part", classes="legend-row highlight-row"):
            html.Span(classes="swatch", style="background: #ffdb1a")
            html.Span("part {{ highlight_part }} (materials panel)", classes="legend-label")
        with html.Div(classes="legend-row"):
            html.Span(classes="swatch swatch-line")
            html.Span("field of view: {{ footprint_text }}", classes="legend-label")
        for name, color in (("sun", SUN_COLOR), ("earth", EARTH_COLOR)):
            with html.Div(v_if=f"{name}_text", classes=f"legend-row {name}-row"):
                html.Span(classes="swatch swatch-line", style=f"background: {color}")
                html.Span(f"{{{{ {name}_text }}}}", classes="legend-label")


def cloud_card() -> None:
    """The point cloud with its colour bar (or the outlier legend)."""
    with v3.VCard(
        classes="view-card cloud-card",
        elevation=1,
        **html_attributes(aria_describedby="cloud-description"),
    ):
        html.P(
            "{{ 'The point cloud: ' + n_target_points.toLocaleString() + ' target points and '"
            " + n_outliers.toLocaleString() + ' outliers (false alarms), coloured by ' + color_by"
            " + '.' }}",
            id="cloud-description",
            classes="sr-only",
        )
        _card_title("Point cloud (target-fixed frame, m)", "cloud_view")
        with html.Div(classes="vtk-box cloud-box"):
            with _view("cloud_view"):
                with vtkw.VtkGeometryRepresentation(
                    id="cloud",
                    property=("{ pointSize: 3, lighting: false }",),
                    actor=("{ visibility: !!cloud_points && n_target_points > 0 }",),
                ):
                    vtkw.VtkMesh("cloud_points", state=(_bin("cloud_points"),))
                with vtkw.VtkGeometryRepresentation(
                    id="outliers",
                    property=("{ pointSize: 5, lighting: false }",),
                    actor=("{ visibility: !!cloud_outliers && n_outliers > 0 }",),
                ):
                    vtkw.VtkMesh("cloud_outliers", state=(_bin("cloud_outliers"),))
                with vtkw.VtkGeometryRepresentation(  # a pinned frame (app.logic.compare)
                    id="pinned",
                    property=("{ pointSize: 2, lighting: false, opacity: 0.35 }",),
                    actor=("{ visibility: !!pinned_cloud && n_pinned_points > 0 }",),
                ):
                    vtkw.VtkMesh("pinned_cloud", state=(_bin("pinned_cloud"),))
            _cloud_legend()


def _cloud_legend() -> None:
    with html.Div(classes="overlay colorbar-overlay"):
        with html.Div(v_if="cloud_colorbar", classes="colorbar"):
            html.Div("{{ cloud_colorbar.title }}", classes="colorbar-title")
            html.Div(classes="colorbar-bar", style=("{ background: cloud_colorbar.gradient }",))
            with html.Div(classes="colorbar-labels"):
                html.Span("{{ cloud_colorbar.lo }}")
                html.Span("{{ cloud_colorbar.hi }}")
        with html.Div(v_else=True, classes="legend-row"):
            html.Span(classes="swatch swatch-target")
            html.Span("target points: {{ n_target_points.toLocaleString() }}")
        with html.Div(classes="legend-row"):
            html.Span(classes="swatch swatch-outlier")
            html.Span("outliers (false alarms): {{ n_outliers.toLocaleString() }}")
        with html.Div(v_if="pinned", classes="legend-row pinned-legend"):
            html.Span(classes="swatch swatch-pinned")
            html.Span("pinned frame (faint): {{ n_pinned_points.toLocaleString() }}")
