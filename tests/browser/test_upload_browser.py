"""Uploading a target mesh from the page in real headless Chromium: the file input sends the
file's bytes, the new target's parts get material drop-downs and the views are redrawn; a bad file
shows a message; "Use built-in MRO" brings the MRO back."""

from __future__ import annotations

import time

import pytest
import trimesh
from support.launch import JS_STATE, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser


def state(page, name: str):
    return page.evaluate(JS_STATE, name)


def test_a_mesh_uploaded_from_the_page_becomes_the_target(page, app_url, tmp_path, artifacts_dir):
    obj = tmp_path / "two parts.obj"
    obj.write_text(
        "v 0 0 0\nv 4 0 0\nv 0 4 0\nv 0 0 4\n"
        "usemtl alpha\nf 1 2 3\nf 1 2 4\nusemtl beta\nf 1 3 4\nf 2 3 4\n"
    )
    box = tmp_path / "box.stl"
    box.write_bytes(trimesh.creation.box(extents=(6, 3, 2)).export(file_type="stl"))
    bad = tmp_path / "broken.glb"
    bad.write_bytes(b"glTF\x02\x00\x00\x00" + b"\xff" * 64)

    page.goto(app_url)
    wait_first_frame(page)
    wait_settled(page)
    page.locator(".reset-button").click()  # the paper scene, whatever an earlier test left
    time.sleep(0.3)
    wait_settled(page)
    page.locator(".upload-panel .v-expansion-panel-title").click()
    file_input = page.locator(".upload-file input[type=file]")

    file_input.set_input_files(str(box))
    page.wait_for_function("() => window.trame.state.get('target_is_upload') === true")
    page.locator(".upload-message").filter(has_text="Loaded 'box.stl': 12 triangles").wait_for()
    wait_settled(page)
    assert state(page, "n_points") > 0 and state(page, "error_message") == ""
    assert len(state(page, "part_names")) == 1
    page.screenshot(path=artifacts_dir / "app-uploaded-box.png")

    file_input.set_input_files(str(bad))
    error = page.locator(".upload-error")
    error.wait_for()
    assert "Upload refused: 'broken.glb': cannot read the .glb file" in error.inner_text()
    assert "Traceback" not in page.content()

    huge = tmp_path / "huge.stl"
    with huge.open("wb") as f:
        f.truncate(33 * 2**20)
    page.locator(".upload-error .v-alert__close button, .upload-error button").first.click()
    file_input.set_input_files(str(huge))
    error.filter(has_text="is 33.0 MiB; uploads are limited to 32 MiB (not sent)").wait_for()
    assert len(state(page, "part_names")) == 1  # still the box

    file_input.set_input_files(str(obj))
    page.wait_for_function("() => (window.trame.state.get('part_names') || []).length === 2")
    wait_settled(page)
    page.locator(".v-expansion-panel-title", has_text="Target materials").click()
    assert page.locator(".material-select").count() == 2

    page.locator(".builtin-button").click()
    page.wait_for_function("() => window.trame.state.get('part_names').includes('foil')")
    wait_settled(page)
    assert not state(page, "target_is_upload") and state(page, "n_points") > 1000
