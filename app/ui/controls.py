"""The drawer: pose and sensor sliders (each with a number field), fidelity, seed, per-part
materials, display choices and the reset to the paper scene."""

from __future__ import annotations

import math

from trame.widgets import client, html
from trame.widgets import vuetify3 as v3

import simcore
from app.logic import preset_text
from app.state import PRESET_CHOICES, SPECS, SUBRAY_CHOICES, ControlSpec
from app.ui import design, flyaround, glossary, lessons
from app.ui.upload import upload_panel
from app.ui.widgets import a11y_attributes, button_toggle, html_attributes, labelled_toggle
from simcore import receivers

SHARE_URL = "trame.utils.lmapdLink ? trame.utils.lmapdLink.url(share_query) : ''"
SLOW_RAYS = 2e6  # rays per flash above which the page warns that updates take seconds


def _label(spec: ControlSpec) -> str:
    return f"{spec.label} ({spec.unit})" if spec.unit else spec.label


def _number_field(key: str, spec: ControlSpec) -> None:
    """A compact number field; the value is sent on change (Enter or leaving the field), and the
    server clamps or refuses it with a message."""
    v3.VTextField(
        model_value=(key,),
        change=f"{key} = $event.target.value",
        type="number",
        density="compact",
        variant="outlined",
        hide_details=True,
        single_line=True,
        style="width: 96px",
        step=spec.step,
        classes=f"value-{key}",
        __events=["change"],
    )


def slider(key: str) -> None:
    """A labelled slider plus number field for one control of ``SPECS``. Distance and pulse
    energy slide on a log scale (their ranges span 2-4 decades)."""
    spec = SPECS[key]
    if spec.log_slider:
        digits = 3
        model = (f"Math.log10(Math.max({key}, 1e-12))",)
        update = f"{key} = Number((10 ** $event).toPrecision({digits}))"
        # (the keys step a hundredth of a decade, Page a tenth: app/static/keyboard.js)
        bounds = {"min": math.log10(spec.lo), "max": math.log10(spec.hi), "step": 0.001}
    else:
        model = (key,)
        update = f"{key} = $event"
        bounds = {"min": spec.lo, "max": spec.hi, "step": spec.step}
    with html.Div(
        classes=f"control control-{key}",
        **a11y_attributes(spec.label, spec.unit, spec.log_slider, key),
    ):
        with html.Div(classes="control-label text-body-2 d-flex align-center"):
            html.Span(_label(spec))
            glossary.info_button(key, spec.label)
        with v3.VSlider(
            model_value=model,
            update_modelValue=update,
            density="compact",
            hide_details=True,
            color="primary",
            track_size=3,
            thumb_size=14,
            classes=f"slider-{key}",
            **bounds,
        ):
            with v3.Template(v_slot_append=True):
                _number_field(key, spec)


def fidelity_choice() -> None:
    """The fidelity preset (its knobs in the tooltips and the hint below), or custom sub-rays."""
    texts = {name: preset_text(name) for name in simcore.PRESETS}
    texts["custom"] = "the fidelity of the scene with the sub-rays per pixel chosen below"
    subrays = "subrays"  # a JS expression: sub-rays per pixel of the chosen preset
    for name, knobs in simcore.PRESETS.items():
        subrays = f"(preset === '{name}' ? {knobs['fidelity.subrays']} : {subrays})"
    with html.Div(classes="control control-preset"):
        items = [
            {"title": name.capitalize(), "value": name, "subtitle": texts[name]}
            for name in PRESET_CHOICES
        ]
        v3.VSelect(
            label="Fidelity preset",
            model_value=("preset",),
            update_modelValue="preset = $event",
            items=("preset_items", items),
            item_props=True,
            density="compact",
            variant="outlined",
            hide_details=True,
            classes="mt-2 preset-select",
        )
        for name in PRESET_CHOICES:
            html.Div(
                texts[name],
                v_if=f"preset === '{name}'",
                classes=f"text-caption hint preset-hint preset-hint-{name}",
            )
    labelled_toggle(
        "Custom: sub-rays per pixel",
        "subrays",
        [(str(n), n, f"subrays-{n}") for n in SUBRAY_CHOICES],
        div_classes="control control-subrays",
        v_if="preset === 'custom'",
    )
    html.Div(
        f"{{{{ (pixels * pixels * {subrays} / 1e6).toFixed(1) }}}} M rays per flash: "
        "expect seconds per update",
        v_if=f"pixels * pixels * {subrays} >= {SLOW_RAYS:g}",
        classes="text-caption text-deep-orange-darken-2 slow-hint",
    )


def seed_field() -> None:
    spec = SPECS["seed"]
    with html.Div(classes="control control-seed d-flex align-center ga-2"):
        v3.VTextField(
            label="Seed (random draws)",
            model_value=("seed",),
            change="seed = $event.target.value",
            type="number",
            density="compact",
            variant="outlined",
            hide_details=True,
            step=spec.step,
            classes="value-seed",
            __events=["change"],
        )
        v3.VBtn(
            icon="mdi-dice-multiple-outline",
            size="small",
            variant="text",
            title="New random seed",
            click="seed = Math.floor(Math.random() * 2147483647)",
        )


def target_choice() -> None:
    """The built-in targets (NASA spacecraft with their thumbnails, calibration shapes) and the
    distance at which the shown target fills the field of view."""
    with html.Div(classes="control control-target d-flex align-center ga-1"):
        v3.VSelect(
            label="Target",
            model_value=("target_choice",),
            update_modelValue="target_choice = $event",
            items=("target_items",),
            placeholder="uploaded mesh",
            density="compact",
            variant="outlined",
            hide_details=True,
            disabled=("upload_busy",),
            classes="target-select",
        )
        v3.VBtn(
            icon="mdi-fit-to-screen-outline",
            size="small",
            variant="text",
            title="Fit the field of view: the distance at which the target just fills it",
            click="trigger('fit_field_of_view')",
            classes="fit-fov",
            **html_attributes(aria_label="Fit the field of view"),
        )


def materials_panel() -> None:
    """One drop-down per target part over the material library."""
    with v3.VExpansionPanels(variant="accordion", classes="mt-2"):
        with v3.VExpansionPanel():
            v3.VExpansionPanelTitle("Target materials (per part)", classes="text-body-2")
            with v3.VExpansionPanelText():
                html.Div(
                    "Point at a part or choose it: the 3D scene shows it in yellow.",
                    classes="hint text-caption mb-2",
                )
                # hovering a part's row or choosing it (focus, a new material) highlights it
                with html.Div(
                    v_for="part in part_names",
                    key="part",
                    mouseenter="part_hover = part",
                    mouseleave="part_hover = null",
                    focusin="part_chosen = part",
                    classes="material-row",
                ):
                    v3.VSelect(
                        label=("part",),
                        hint=("part_info[part] || ''",),
                        persistent_hint=True,
                        model_value=("materials[part]",),
                        update_modelValue=(
                            "materials = {...materials, [part]: $event}; part_chosen = part"
                        ),
                        items=("material_items",),
                        density="compact",
                        variant="outlined",
                        classes="mb-2 material-select",
                    )


def _explained_toggle(label: str, key: str, choices: list) -> None:
    """A labelled one-of-several choice with its glossary button beside the label."""
    with html.Div(classes=f"control control-{key}"):
        with html.Div(classes="control-label text-body-2 d-flex align-center"):
            html.Span(label)
            glossary.info_button(key, label)
        button_toggle(key, choices, label=label)


def display_choices() -> None:
    with html.Div(classes="control"):  # five choices: the buttons wrap in the drawer
        with html.Div(classes="control-label text-body-2 d-flex align-center"):
            html.Span("Colour points by")
            glossary.info_button("color_by", "Colour points by")
        button_toggle(
            "color_by",
            [
                ("Range", "range", ""),
                ("SNR", "snr", ""),
                ("Outlier flag", "outlier", ""),
                ("Range error", "range_error", ""),
                ("Part", "part", ""),
            ],
            classes="wrap-toggle",
            label="Colour points by",
        )


def share_panel() -> None:
    """The link that reproduces the current frame (settings in the query string), to copy
    (app/static/link.js makes it)."""
    client.ClientStateChange(value="share_query", change="link_copied = ''")  # a new link
    with v3.VExpansionPanels(variant="accordion", classes="mt-2 share-panel"):
        with v3.VExpansionPanel():
            v3.VExpansionPanelTitle("Share this scene (link)", classes="text-body-2")
            with v3.VExpansionPanelText():
                v3.VTextField(
                    label="Link to this scene",
                    model_value=(SHARE_URL,),
                    readonly=True,
                    density="compact",
                    variant="outlined",
                    hide_details=True,
                    classes="share-link mb-2",
                )
                v3.VBtn(
                    "Copy link",
                    prepend_icon="mdi-link-variant",
                    size="small",
                    variant="tonal",
                    color="primary",
                    click=(
                        "trame.utils.lmapdCopy(trame.utils.lmapdLink.url(share_query))"
                        ".then((m) => { link_copied = m; })"
                    ),
                    classes="copy-link",
                )
                html.Span(
                    "{{ link_copied }}",
                    v_if="link_copied",
                    classes="text-caption text-success ml-2 link-copied",
                    **html_attributes(role="status"),
                )
                html.Div(
                    "Whoever opens it sees this pose, array, energy, TNR, fidelity, seed and "
                    "materials: the same points. It lists only what differs from the start.",
                    classes="text-caption hint mt-1",
                )


DOWNLOADS = (  # (button text, file name, trigger call, MIME type, CSS class)
    (
        "Cloud PLY",
        "lmapd-cloud.ply",
        "trigger('export_cloud', ['ply'])",
        "application/octet-stream",
        "export-ply",
    ),
    (
        "Cloud LAS",
        "lmapd-cloud.las",
        "trigger('export_cloud', ['las'])",
        "application/octet-stream",
        "export-las",
    ),
    (
        "Waveforms CSV",
        "lmapd-waveforms.csv",
        "trigger('export_waveforms')",
        "text/csv",
        "export-csv",
    ),
    (
        "Scene TOML",
        "lmapd-scene.toml",
        "trigger('export_scene')",
        "application/toml",
        "export-toml",
    ),
)


def downloads() -> None:
    """Download buttons: the shown frame's cloud, the selected pixels' waveforms, the scene."""
    with html.Div(classes="control d-flex flex-wrap ga-1 downloads"):
        for text, name, call, mime, css in DOWNLOADS:
            v3.VBtn(
                text,
                prepend_icon="mdi-download",
                size="x-small",
                variant="tonal",
                click=f"trame.utils.lmapdLink.save('{name}', {call}, '{mime}')",
                classes=css,
            )


def sunlight() -> None:
    """The Sun (none: the paper's dark sky; manual: azimuth and elevation in the target's body
    frame; from the orbit: the epoch's ephemeris and the fly-around's time) and the receiver's
    band-pass filter, which decides how much of its light gets in."""
    _explained_toggle(
        "Sun",
        "sun_mode",
        [
            ("None", "none", "sun-none"),
            ("Manual", "manual", "sun-manual"),
            ("Orbit", "orbit", "sun-orbit"),
        ],
    )
    # a choice's own controls are rendered only while it is chosen (v-if, not v-show): a new
    # page builds only the sliders it shows
    with html.Div(v_if="sun_mode === 'manual'", classes="sun-manual-controls"):
        slider("sun_azimuth_deg")
        slider("sun_elevation_deg")
    with html.Div(v_if="sun_mode !== 'none'", classes="sun-filter-controls"):
        slider("filter_width_nm")
        html.Div(
            "Orbit: the Sun from the JPL DE421 ephemeris at the scene's epoch and, in fly-around "
            "mode, each frame's time; in the Earth's shadow there is none. The sunlit Earth "
            "behind the target adds its light. Array image: Background shows it per pixel.",
            classes="text-caption hint",
        )


def receiver_choice() -> None:
    """The receiver: one button per registered receiver (the paper's linear-mode APD array, a
    Geiger-mode single-photon array, ...), and under it the selected one's own controls and
    caption, all from its declaration (``simcore.receivers``)."""
    declared = receivers.receivers()
    _explained_toggle(
        "Receiver",
        "receiver_kind",
        [(r.label or r.kind, r.kind, f"receiver-{r.short or r.kind}") for r in declared],
    )
    for r in declared:
        if not r.controls:
            continue
        with html.Div(
            v_if=f"receiver_kind === '{r.kind}'", classes=f"{r.short or r.kind}-controls"
        ):
            for control in r.controls:
                slider(control.name)
            if r.hint:
                html.Div(r.hint, classes="text-caption hint")


def section(title: str) -> None:
    html.Div(title, classes="section-title text-overline")


# the drawer's controls are built once the page's first frame is on screen (app/static/frame.js)
CONTROLS_READY = "trame.utils.lmapd && trame.utils.lmapd.page.controls"


def drawer_content() -> None:
    """Everything in the drawer, top to bottom. Its controls are built once the page's first
    frame is on screen (``CONTROLS_READY``): about 0.15 s of the page's CPU that the first
    picture does not need (the views are built first)."""
    html.Div(
        "Loading the controls…",
        v_if=f"!({CONTROLS_READY})",
        classes="pa-3 text-medium-emphasis controls-loading",
        **html_attributes(role="status"),
    )
    with html.Div(v_if=CONTROLS_READY, classes="pa-3 controls"):
        v3.VBtn(
            "{{ scene_name === 'paper' ? 'Reset to paper scene' : 'Reset to ' + scene_name }}",
            prepend_icon="mdi-restore",
            block=True,
            variant="tonal",
            color="primary",
            click="trigger('reset_controls')",
            classes="reset-button mb-2",
        )
        lessons.lessons_panel()
        target_choice()
        flyaround.mode_switch()
        with html.Div(v_show="mode !== 'flyaround'", classes="single-pose"):
            section("Pose of the target")
            for key in ("pitch_deg", "azimuth_deg", "distance_m"):
                slider(key)
        flyaround.flyaround_panel()
        section("Laser and detector")
        for key in ("pixels", "pulse_energy_mj", "tnr"):
            slider(key)
        fidelity_choice()
        seed_field()
        section("Receiver")
        receiver_choice()
        section("Sunlight (background light)")
        sunlight()
        materials_panel()
        upload_panel()
        share_panel()
        design.study_chooser()
        section("Display")
        display_choices()
        section("Download (the frame shown)")
        downloads()
        html.Div(
            "3D views: drag to rotate, right-drag (or Ctrl + wheel, or click the view, then "
            "wheel) to zoom, middle- or Alt-drag to pan; the wheel alone scrolls the page. The "
            "camera icon resets the view. Sliders update the views while you drag; "
            "number fields apply on Enter, and values outside a range are clamped with a "
            "message.",
            classes="text-caption help-text mt-3",
        )
