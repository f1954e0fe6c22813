"""Small building blocks shared by the panels."""

from __future__ import annotations

from collections.abc import Sequence

from trame.widgets import html
from trame.widgets import vuetify3 as v3

# (button text, value, extra CSS classes of the button)
Choice = tuple[str, object, str]


def button_toggle(
    key: str, choices: Sequence[Choice], size: str = "small", classes: str = ""
) -> None:
    """A mandatory one-of-several button group bound to state ``key``."""
    with v3.VBtnToggle(
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
        button_toggle(key, choices)
