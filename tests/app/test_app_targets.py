"""Targets in the app: a built-in spacecraft picked from the drop-down becomes the target (off
the event loop), the parts panel says each part's share of the area, "fit the field of view"
sets the distance at which the target fills it, an upload's messages name its file."""

from __future__ import annotations

import math
import threading

import pytest
import trimesh
from support.app_helpers import settle, small_app

from simcore.scene import Target
from simcore.target import builtin_targets, load_target


@pytest.fixture(scope="module")
def app():
    with small_app() as lmapd:
        yield lmapd


def box_stl() -> bytes:
    return trimesh.creation.box(extents=(2.0, 1.0, 0.5)).export(file_type="stl")


def pick(app, name):
    with app.state:
        app.state.target_choice = name
    settle(app)


def test_the_drop_down_lists_the_catalogue_with_sizes_and_thumbnails(app):
    items = app.state.target_items
    assert [i["value"] for i in items] == builtin_targets()
    tdrs = next(i for i in items if i["value"] == "tdrs")
    assert "m)" in tdrs["title"] and tdrs["prependAvatar"].startswith("data:image/png;base64,")
    assert app.state.target_choice == "mro"


def test_a_built_in_spacecraft_becomes_the_target_and_the_parts_say_their_share(app):
    pick(app, "tess")
    result = app.logic.last_frame.result
    assert result.scene.target.mesh == "tess"
    assert result.target.name.startswith("Transiting Exoplanet")
    assert app.state.target_name.startswith("Transiting Exoplanet") and "NASA" in app.state.credit
    shares = [float(app.state.part_info[p].split(" %")[0]) for p in app.state.part_names]
    assert math.isclose(sum(shares), 100.0, abs_tol=0.1 * len(shares))
    assert app.state.n_points > 0 and app.state.upload_error == ""
    pick(app, "mro")
    assert app.logic.last_frame.result.scene.target.mesh == "mro"


def test_fit_the_field_of_view_sets_the_distance_where_the_target_fills_it(app):
    app.logic.fit_field_of_view()
    settle(app)
    mesh = app.engine.model.mesh
    result = app.logic.last_frame.result
    d = result.scene.pose.distance_m
    half_fov = result.scene.receive.fov_rad / 2
    radius = max(((mesh.vertices - mesh.bounds.mean(axis=0)) ** 2).sum(axis=1)) ** 0.5
    assert math.isclose(math.sin(half_fov) * d, radius, rel_tol=1e-3)  # 0.1 m rounding
    with app.state:
        app.state.distance_m = 500.0
    settle(app)


def test_an_unknown_choice_is_refused_with_a_message(app):
    pick(app, "../../etc/passwd")
    assert app.state.upload_error == "No built-in target '../../etc/passwd'"
    assert app.logic.last_frame.result.scene.target.mesh == "mro"


def test_an_uploads_messages_name_its_file_and_the_input_is_emptied_for_a_new_pick(app):
    before = app.state.upload_input_key
    with app.state:
        app.state.upload_file = {
            "name": "C:\\meshes\\tiny.stl",
            "size": 10,
            "content": b"solid x",
        }
    settle(app)
    assert app.state.upload_error.startswith("Upload refused: 'tiny.stl': ")
    assert app.state.upload_input_key == before + 1
    data = box_stl()
    with app.state:
        app.state.upload_file = {"name": "box.stl", "size": len(data), "content": data}
    settle(app)
    assert app.state.upload_message.startswith("Loaded 'box.stl': 12 triangles")
    # an upload: the drop-down names it (an item of its own, while it is shown)
    assert app.state.target_choice == "upload:box.stl"
    assert {"title": "box.stl (uploaded)", "value": "upload:box.stl"} in app.state.target_items
    assert app.state.target_name == "box.stl (uploaded)"
    app.uploads.use_builtin()
    settle(app)
    assert app.state.target_choice == "mro"
    assert not any(i["value"].startswith("upload:") for i in app.state.target_items)


def test_a_page_that_sees_an_uploads_parts_or_message_sees_busy(app, monkeypatch):
    """An upload's parts reach the page with ``busy`` (its frame is under way), its message
    after them: a page that sees either never sees the old target's parts or an idle server
    with the old target's frame (a browser test waiting for the message, then for the page to
    settle, read the MRO's parts). Its frame waits until the upload is shown."""
    gate = threading.Event()
    pushes = []
    with small_app(model=app.uploads.builtin.engine.model) as fresh:
        compute = fresh.logic.runner._compute

        def gated(request):
            assert gate.wait(60)
            return compute(request)

        monkeypatch.setattr(fresh.logic.runner, "_compute", gated)

        @fresh.state.change("upload_message", "part_names")
        def record(upload_message="", part_names=(), busy=False, **_):
            pushes.append((upload_message, list(part_names), busy))

        data = box_stl()
        # called, not set in the state: its load finishes outside any flush of the state, as
        # on the server (a future's callback), where each nested flush is a push of its own;
        # without a server it has finished when on_upload returns
        fresh.uploads.on_upload({"name": "box.stl", "size": len(data), "content": data})
        gate.set()
        settle(fresh)
        parts = list(fresh.state.part_names)
        assert len(parts) == 1 and not fresh.state.busy
    assert pushes and all(busy for _, _, busy in pushes), pushes
    assert [names for text, names, _ in pushes if text.startswith("Loaded 'box")] == [parts]


TWO_OBJECTS_OBJ = b"""o box
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
f 1 2 3
f 1 3 4
o cylinder
v 3 0 0
v 4 0 0
v 4 1 0
v 3 1 1
f 5 6 7
f 5 7 8
"""


def test_each_named_object_of_an_obj_is_a_part_named_alike_by_the_cli_and_the_app(app, tmp_path):
    path = tmp_path / "two.obj"
    path.write_bytes(TWO_OBJECTS_OBJ)
    cli_parts = load_target(Target(mesh=str(path))).part_names
    assert sorted(cli_parts) == ["box", "cylinder"]
    with app.state:
        app.state.upload_file = {
            "name": "two.obj",
            "size": len(TWO_OBJECTS_OBJ),
            "content": TWO_OBJECTS_OBJ,
        }
    settle(app)
    assert app.state.upload_error == "" and sorted(app.state.part_names) == sorted(cli_parts)
    # two parts, two materials: each reaches the scene
    materials = {"box": "solar_panel", "cylinder": "coating_1"}
    with app.state:
        app.state.materials = materials
    settle(app)
    model = app.logic.last_frame.result.target
    assert dict(zip(model.part_names, model.part_materials, strict=True)) == materials
    app.uploads.use_builtin()
    settle(app)
