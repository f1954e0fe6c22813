"""The drawer's mode switch (single frame / fly-around) and the fly-around panel: time slider,
play/pause, the J2 switch, a readout of the frame's time, distance and attitude, a map of the
orbits, and the "Track pose" switch with its readout and the errors along the track (the true
and estimated target frames are drawn in the 3D scene: ``app.ui.views3d``)."""

from __future__ import annotations

from trame.widgets import html, plotly
from trame.widgets import vuetify3 as v3

from app.payloads.track import ESTIMATE_COLOR, TRUE_COLOR
from app.ui.widgets import a11y_attributes, button_toggle, html_attributes

FOV_HINT = (
    "Pose from the two orbits of Table 3 (lidar tracking the target). At about 200 m the 30 mrad "
    "field of view covers only about 6 m of the 15 m MRO: the views show part of the target, as "
    "expected. Pitch, azimuth and distance come from the orbit; the other controls still apply."
)


def mode_switch() -> None:
    with html.Div(classes="control control-mode"):
        html.Div("Mode", classes="control-label text-body-2")
        button_toggle(
            "mode",
            [
                ("Single frame", "single", "mode-single"),
                ("Fly-around", "flyaround", "mode-flyaround"),
            ],
            classes="mode-toggle",
            label="Mode",
        )


def flyaround_panel() -> None:
    """Shown in fly-around mode only (rendered only then: v-if, as the drawer's other panels of
    one choice, so a new page does not build its sliders and orbit chart hidden)."""
    with html.Div(v_if="mode === 'flyaround'", classes="flyaround-panel"):
        html.Div("Fly-around (one orbit)", classes="section-title text-overline")
        with html.Div(
            classes="control control-fly_t_s", **a11y_attributes("Time since the epoch", "s")
        ):
            html.Div("Time (s) since the epoch", classes="control-label text-body-2")
            with v3.VSlider(
                model_value=("fly_t_s",),
                update_modelValue="fly_t_s = $event",
                min=0,
                max=("fly_t_max_s",),
                step=("fly_interval_s",),
                density="compact",
                hide_details=True,
                color="primary",
                track_size=3,
                thumb_size=14,
                classes="slider-fly_t_s",
            ):
                with v3.Template(v_slot_prepend=True):
                    v3.VBtn(
                        icon=("fly_playing ? 'mdi-pause' : 'mdi-play'",),
                        size="small",
                        variant="tonal",
                        color="primary",
                        title=("fly_playing ? 'Pause' : 'Play: step through the frames'",),
                        click="fly_playing = !fly_playing",
                        classes="fly-play",
                    )
                with v3.Template(v_slot_append=True):
                    html.Span(
                        "{{ fly_t_s }} s",
                        classes="text-body-2 fly-t-value",
                        style="min-width: 58px; text-align: right",
                    )
        v3.VCheckbox(
            model_value=("fly_j2",),
            update_modelValue="fly_j2 = $event",
            label="J2 secular drift of the orbits",
            density="compact",
            hide_details=True,
            color="primary",
            classes="fly-j2",
        )
        with v3.VTable(density="compact", classes="stats-table fly-readout"):
            with html.Tbody():
                for label, key in (
                    ("Time", "t"),
                    ("Distance", "distance"),
                    ("Attitude x, y′, z″", "angles"),
                    ("Field of view across", "fov"),
                ):
                    with html.Tr():
                        html.Td(label)
                        html.Td(f"{{{{ fly_readout.{key} }}}}", classes="stat-value")
        html.Div(FOV_HINT, classes="text-caption hint fly-hint mt-1")
        pose_track()
        orbit_map()


def pose_track() -> None:
    """The "Track pose" switch: each frame shown registered to the target's model in the
    background (app.logic.pose_track); its errors and a chart along the track so far."""
    v3.VSwitch(
        model_value=("fly_track",),
        update_modelValue="fly_track = $event",
        label="Track pose",
        density="compact",
        hide_details=True,
        color="primary",
        classes="fly-track",
        title="Register each frame's cloud to the target's model, seeded by the frame before",
    )  # its accessible name: the label's "Track pose"
    with html.Div(v_if="fly_track", classes="fly-track-panel"):
        html.Div(
            "{{ fly_track_text || 'Tracking the frame shown...' }}",
            classes="text-body-2 fly-track-text",
            **html_attributes(aria_live="polite"),
        )
        with html.Div(classes="text-caption hint"):
            html.Span("In the 3D scene: the true target frame ")
            html.Span("(green)", style=f"color: {TRUE_COLOR}; font-weight: 500")
            html.Span(" and the estimated one ")
            html.Span("(magenta)", style=f"color: {ESTIMATE_COLOR}; font-weight: 500")
            html.Span("; the longest axis is x, the shortest z.")
        with html.Div(v_if="fly_track_chart", classes="chart-box fly-track-box"):
            plotly.Figure(
                state_variable_name="fly_track_chart", display_mode_bar=False, responsive=True
            )


def orbit_map() -> None:
    """The two orbits around the Earth and the lidar's path around the target (app.payloads.orbits),
    with where they are at the frame's time."""
    with html.Div(v_if="fly_map", classes="fly-map"):
        html.Div(
            "Top: the Earth and the two orbits (the target's dot: now). Bottom: the lidar's path "
            "around the target over the orbit, seen from the target (its dot: now).",
            classes="text-caption hint mt-1",
        )
        with html.Div(classes="chart-box fly-map-box"):
            plotly.Figure(state_variable_name="fly_map", display_mode_bar=False, responsive=True)
