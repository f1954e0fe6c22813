"""The drawer's "Target mesh" panel: upload a glTF/OBJ/STL/PLY mesh, its scale in metres per mesh
unit, and the way back to the built-in MRO (logic: app.logic.upload)."""

from __future__ import annotations

from trame.widgets import html
from trame.widgets import vuetify3 as v3

from app.logic import ALLOWED_SUFFIXES, SCALE_RANGE

# A file over the size cap is refused in the page, before its bytes are read and sent (the server
# checks again: a client need not run this page).
ON_FILE = (
    "upload_file = ([].concat($event || [])[0] || {}).size > upload_max_mib * 1048576"
    " ? (upload_error = 'Upload refused: the file is '"
    " + ([].concat($event)[0].size / 1048576).toFixed(1)"
    " + ' MiB; uploads are limited to ' + upload_max_mib + ' MiB (not sent)', null)"
    " : $event"
)


def upload_panel() -> None:
    with v3.VExpansionPanels(variant="accordion", classes="mt-2 upload-panel"):
        with v3.VExpansionPanel():
            v3.VExpansionPanelTitle("Target mesh (upload your own)", classes="text-body-2")
            with v3.VExpansionPanelText():
                v3.VFileInput(
                    key=("upload_input_key",),  # re-created empty after each pick: the same
                    __properties=["key"],  # file can be picked again
                    label="glTF (Draco too), OBJ, STL or PLY mesh",
                    accept=",".join(ALLOWED_SUFFIXES),
                    update_modelValue=ON_FILE,
                    disabled=("upload_busy",),
                    density="compact",
                    variant="outlined",
                    hide_details=True,
                    prepend_icon="",
                    prepend_inner_icon="mdi-upload",
                    show_size=True,
                    classes="mb-2 upload-file",
                )
                v3.VTextField(
                    label="Scale (m per mesh unit)",
                    model_value=("upload_scale",),
                    change="upload_scale = $event.target.value",
                    type="number",
                    min=SCALE_RANGE[0],
                    max=SCALE_RANGE[1],
                    density="compact",
                    variant="outlined",
                    hide_details=True,
                    classes="mb-2 upload-scale",
                    __events=["change"],
                )
                html.Div(
                    "At most {{ upload_max_mib }} MiB and "
                    "{{ upload_max_faces.toLocaleString() }} triangles; the parts get the "
                    "material drop-downs above.",
                    classes="text-caption hint mb-1",
                )
                html.Div(
                    "Loading the mesh…", v_show="upload_busy", classes="text-caption upload-busy"
                )
                v3.VAlert(
                    "{{ upload_message }}",
                    v_if="upload_message",
                    type="success",
                    density="compact",
                    variant="tonal",
                    classes="mb-2 upload-message",
                )
                v3.VAlert(
                    "{{ upload_error }}",
                    v_if="upload_error",
                    type="error",
                    density="compact",
                    variant="tonal",
                    closable=True,
                    click_close="upload_error = ''",
                    classes="mb-2 upload-error",
                    __events=[("click_close", "click:close")],
                )
                v3.VBtn(
                    "Use built-in MRO",
                    prepend_icon="mdi-satellite-variant",
                    block=True,
                    variant="tonal",
                    disabled=("!target_is_upload",),
                    click="trigger('use_builtin_target')",
                    classes="builtin-button",
                )
