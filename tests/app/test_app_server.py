"""The app through its trame server state, without a browser: changes in the state run the
simulation off the UI thread and come back as view state; bad values are clamped or refused with
a message; a failing computation shows a message and keeps the last good frame; stale frames are
dropped; frames are paced by the page's acknowledgements."""

from __future__ import annotations

import threading

import pytest
from support.app_helpers import change, settle

import simcore
from app.engine import Engine
from app.main import LmapdApp, parse_args

SMALL = {"pixels": 48, "fidelity.subrays": 1}


@pytest.fixture(scope="module")
def engine():
    return Engine(simcore.load_scene())  # loading the MRO once for the module


@pytest.fixture
def app(engine):
    """An app on the paper scene at 48 x 48 pixels, its state ready, frames applied at once."""
    scene = simcore.with_overrides(simcore.load_scene(), SMALL)
    fresh = Engine(scene, model=engine.model)  # its own Pipeline, the MRO already loaded
    lmapd = LmapdApp(scene, engine=fresh, flow_control=False, debounce_s=0.0)
    lmapd.state.ready()  # fires the change handlers once, like a server start
    settle(lmapd)
    yield lmapd
    lmapd.logic.runner.close()


def test_the_first_frame_fills_every_view(app):
    s = app.state
    assert s.frame_key == "g1" and not s.busy and s.error_message == ""
    assert s.n_points > 0 and s.cloud_points["mesh"]["points"]["shape"][1] == 3
    assert s.target_polys["shape"] == [4 * len(app.engine.model.mesh.faces)]
    assert s.seen_facets["field"]["location"] == "CellData"
    assert s.array_image["pixels"] == 48 and s.array_image["png"].startswith(b"\x89PNG")
    assert len(s.selected_pixels) == 1 and s.waveforms["data"]
    assert [r["stage"] for r in s.stages][: len(simcore.STAGES)] == list(simcore.STAGES)
    assert s.credit == "3D model: Courtesy NASA/JPL-Caltech (NASA 3D Resources)"
    assert s.input_message == ""


def test_moving_the_distance_changes_the_point_cloud(app):
    before = app.state.n_points
    change(app, distance_m=1500)
    assert app.state.n_points != before
    assert app.logic.last_frame.result.scene.pose.distance_m == 1500
    assert app.state.frame_key == "g2"


def test_the_simulation_runs_in_the_worker_thread(app, monkeypatch):
    threads: list[str] = []
    compute = app.logic.runner._compute

    def spy(request):
        threads.append(threading.current_thread().name)
        return compute(request)

    monkeypatch.setattr(app.logic.runner, "_compute", spy)
    change(app, tnr=6)
    assert threads == ["lmapd-runner"]


def test_the_pulse_energy_in_mj_reaches_the_scene_in_joules(app):
    change(app, pulse_energy_mj=0.2)
    assert app.logic.last_frame.result.scene.laser.pulse_energy_j == pytest.approx(2e-4)


def test_an_out_of_range_value_from_the_websocket_is_clamped_with_a_message(app):
    change(app, distance_m=1e9, pixels=-3)
    s = app.state
    assert s.distance_m == 5000 and s.pixels == 16
    assert "Distance 1e+09 is outside 20 to 5000 m; set to 5000 m" in s.input_message
    assert "Pixels -3 is outside 16 to 512" in s.input_message
    assert app.logic.last_frame.result.pixels == 16


def test_a_value_that_is_no_number_is_refused_and_the_old_one_restored(app):
    change(app, tnr="loud")
    assert app.state.tnr == 5.0
    assert "TNR: 'loud' is not a number; kept 5" in app.state.input_message


def test_a_failing_computation_shows_a_message_and_keeps_the_last_good_frame(app, monkeypatch):
    good = app.logic.last_frame
    good_points = app.state.n_points

    def broken(request):
        raise simcore.SceneError("pose.distance_m = 1e9 is out of range; valid range (0, 1e6] m")

    monkeypatch.setattr(app.logic.runner, "_compute", broken)
    change(app, distance_m=900)
    s = app.state
    assert s.error_message.startswith("Simulation failed: pose.distance_m = 1e9 is out of range")
    assert "showing the last good result" in s.error_message
    assert "Traceback" not in s.error_message
    assert app.logic.last_frame is good and s.n_points == good_points and not s.busy


def test_an_unexpected_exception_is_shown_by_type_without_a_trace(app, monkeypatch):
    def broken(request):
        raise ZeroDivisionError("division by zero")

    monkeypatch.setattr(app.logic.runner, "_compute", broken)
    change(app, seed=3)
    assert app.state.error_message.startswith("Simulation failed (ZeroDivisionError)")


def test_the_next_good_frame_clears_the_error(app, monkeypatch):
    compute = app.logic.runner._compute
    monkeypatch.setattr(app.logic.runner, "_compute", lambda r: 1 / 0)
    change(app, seed=4)
    assert app.state.error_message
    monkeypatch.setattr(app.logic.runner, "_compute", compute)
    change(app, seed=5)
    assert app.state.error_message == "" and app.logic.last_frame.result.scene.seed == 5


def test_a_stale_outcome_is_not_applied(app):
    logic = app.logic
    old = logic.last_frame
    from app.runner import Outcome

    stale = Outcome(generation=logic.runner.generation - 1, value=old)
    pushed = logic.n_frames_pushed
    logic.apply_outcome(stale)
    assert logic.n_frames_pushed == pushed


def test_clicks_on_the_array_select_pixels_and_draw_their_waveforms(app):
    attrs = app.logic.last_frame.result.attributes
    target = ~attrs["is_outlier"]
    (r1, r2), (c1, c2) = attrs["row"][target][[0, -1]], attrs["col"][target][[0, -1]]
    app.logic.on_pixel_click(r1, c1, False)
    assert app.state.selected_pixels == [[r1, c1]]
    app.logic.on_pixel_click(r2, c2, True)
    assert app.state.selected_pixels == [[r1, c1], [r2, c2]]
    names = [t["name"] for t in app.state.waveforms["data"]]
    assert any(n.startswith(f"({r1}, {c1})") for n in names)
    assert any(n.startswith(f"({r2}, {c2})") for n in names)
    app.logic.on_pixel_click(999, 0, False)  # outside the array: ignored
    app.logic.on_pixel_click("x", None, False)
    assert len(app.state.selected_pixels) == 2


def test_the_selection_survives_a_new_frame_and_follows_a_new_array_size(app):
    app.logic.on_pixel_click(24, 30, False)
    change(app, tnr=4)
    assert app.state.selected_pixels == [[24, 30]]
    change(app, pixels=96)
    assert app.state.selected_pixels == [[49, 61]]  # the same spot of the field of view


def test_a_garbage_selection_from_the_websocket_falls_back_to_the_default_pixel(app):
    with app.state:
        app.state.selected_pixels = "garbage"
    change(app, tnr=4.5)
    assert len(app.state.selected_pixels) == 1 and app.state.error_message == ""


def test_a_click_during_a_computation_is_not_undone_by_its_frame(app):
    logic = app.logic
    with app.state:
        app.state.tnr = 4.2  # submitted with the current selection ...
    logic.on_pixel_click(10, 11, False)  # ... then the user clicks before the frame is back
    settle(app)
    assert app.state.selected_pixels == [[10, 11]]
    assert app.state.waveforms["data"][0]["name"].startswith("(10, 11)")


def test_the_materials_drop_down_changes_one_part(app):
    materials = {**app.state.materials, "foil": "lambertian"}
    change(app, materials=materials)
    result = app.logic.last_frame.result
    assert dict(result.scene.target.materials)["foil"] == "lambertian"
    change(app, materials={**materials, "foil": "mithril"})
    assert app.state.materials["foil"] == "lambertian"
    assert "'mithril' is not in the material library" in app.state.input_message


def test_reset_restores_the_starting_scene(app):
    change(app, distance_m=1200, tnr=8, subrays=16)
    app.logic.reset_controls()
    settle(app)
    s = app.state
    assert (s.distance_m, s.tnr, s.subrays, s.pixels) == (500.0, 5.0, 1, 48)
    assert app.logic.last_frame.result.scene.pose.distance_m == 500.0


class StoppedClock:
    """The pacer's clock, moved only by the test: a frame in flight stops counting after the
    pacer's ack timeout of this clock, never because the machine is slow (under load a frame
    took 0.4 s, so the first frame sent had timed out before the third came and was sent)."""

    def __init__(self) -> None:
        self.now_s = 0.0

    def __call__(self) -> float:
        return self.now_s


def test_frames_wait_for_the_pages_acknowledgement_and_only_the_newest_waits(app):
    logic = app.logic
    logic.pacer.enabled, logic.pacer.max_in_flight = True, 2
    logic.pacer.clock = StoppedClock()  # only the page's reports let frames go
    logic.on_frame_shown(app.state.frame_key)  # the page drew the current frame
    change(app, tnr=6)  # sent: nothing in flight
    first = app.state.frame_key
    change(app, tnr=6.5)  # sent: one frame in flight
    second = app.state.frame_key
    change(app, wait_busy=False, tnr=7)  # waits: two frames in flight
    change(app, wait_busy=False, tnr=8)  # replaces the waiting frame
    assert app.state.frame_key == second != first
    assert logic.pacer.held is not None and app.state.busy
    logic.on_frame_shown(first)  # one frame drawn: the newest waiting one goes
    assert logic.last_frame.result.scene.timing.tnr == 8 and not app.state.busy
    assert logic.pacer.held is None


def test_a_page_that_never_reports_does_not_block_frames_for_long(app):
    logic = app.logic
    logic.pacer.enabled, logic.pacer.max_in_flight, logic.pacer.ack_timeout_s = True, 1, 0.05
    logic.pacer.clock = clock = StoppedClock()
    logic.on_frame_shown(app.state.frame_key)
    change(app, tnr=6)  # sent; the page never reports it drawn
    change(app, wait_busy=False, tnr=7)  # waits for a report that never comes ...
    assert logic.pacer.held is not None
    clock.now_s += 0.06
    change(app, tnr=7.5)  # ... but only ack_timeout_s: the next frame goes out
    assert logic.last_frame.result.scene.timing.tnr == 7.5


@pytest.mark.parametrize("token", ["-starts-with-a-dash", "--also", "plain_token-0"])
def test_the_server_reads_any_token_as_its_key(app, token):
    from app.server.addresses import trame_arguments

    args, _ = app.server.cli.parse_known_args(trame_arguments("127.0.0.1", 8123, token))
    assert (args.authKey, args.host, args.port, args.timeout) == (token, "127.0.0.1", 8123, 0)


def test_the_command_line_defaults_to_localhost_8080_and_the_paper_scene():
    args = parse_args([])
    assert (args.host, args.port, args.scene) == ("127.0.0.1", 8080, None)
    args = parse_args(["--host", "0.0.0.0", "--port", "9000", "--scene", "paper"])
    assert (args.host, args.port, args.scene) == ("0.0.0.0", 9000, "paper")


def test_a_bad_scene_file_exits_with_a_message_not_a_trace(capsys, tmp_path):
    from app.main import main

    assert main(["--scene", str(tmp_path / "missing.toml")]) == 2
    err = capsys.readouterr().err
    assert err.startswith("lmapd app: scene file not found") and "Traceback" not in err
