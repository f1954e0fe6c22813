"""Small building blocks shared by the panels."""

from __future__ import annotations

from collections.abc import Sequence

from trame.widgets import html
from trame.widgets import vuetify3 as v3

SPOKEN_UNITS = {"deg": "degrees", "per side": "pixels per side"}  # what a screen reader says


def html_attributes(**attrs: str) -> dict:
    """Keyword arguments that put plain HTML attributes on a trame widget (``aria_label`` ->
    ``aria-label``): a widget drops keywords it does not declare unless ``__properties`` names
    them."""
    return {**attrs, "__properties": [(key, key.replace("_", "-")) for key in attrs]}


def a11y_attributes(
    name: str, unit: str = "", log_scale: bool = False, state_key: str = ""
) -> dict:
    """The data attributes from which the page's accessibility script names a control's slider
    and number field and speaks the slider's value with its unit (app/static/a11y.js);
    a log slider's state key lets its Page keys step a tenth of a decade
    (app/static/keyboard.js)."""
    attrs = {"data_a11y_name": name, "data_a11y_unit": SPOKEN_UNITS.get(unit, unit)}
    if log_scale:
        attrs["data_a11y_log"] = "1"
        attrs["data_state_key"] = state_key
    return html_attributes(**attrs)


# (button text, value, extra CSS classes of the button)
Choice = tuple[str, object, str]


def button_toggle(
    key: str, choices: Sequence[Choice], size: str = "small", classes: str = "", label: str = ""
) -> None:
    """A mandatory one-of-several button group bound to state ``key`` (``label``: its name for
    screen readers)."""
    with v3.VBtnToggle(
        **html_attributes(role="group", aria_label=label or key),
        model_value=(key,),
        update_modelValue=f"{key} = $event",
        mandatory=True,
        density="compact",
        color="primary",
        variant="outlined",
        divided=True,
        classes=classes,
    ):
        for text, value, btn_classes in choices:
            v3.VBtn(text, value=value, size=size, classes=btn_classes)


def labelled_toggle(
    label: str, key: str, choices: Sequence[Choice], div_classes: str = "control", **div_attrs
) -> None:
    """A control label above a :func:`button_toggle`."""
    with html.Div(classes=div_classes, **div_attrs):
        html.Div(label, classes="control-label text-body-2")
        button_toggle(key, choices, label=label)
