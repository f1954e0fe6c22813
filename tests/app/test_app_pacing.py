"""Frame pacing on its own (app.logic.pacing.FramePacer), without a server or a page."""

import time

from app.logic.pacing import FramePacer


def test_frames_go_until_max_in_flight_are_unreported_then_wait():
    pacer = FramePacer(max_in_flight=2, ack_timeout_s=60.0)
    assert pacer.wait_s() == 0
    pacer.sent("g1")
    assert pacer.wait_s() == 0
    pacer.sent("g2")
    assert 59.0 < pacer.wait_s() <= 60.0


def test_a_drawn_report_frees_that_frame_and_every_older_one():
    pacer = FramePacer(max_in_flight=2, ack_timeout_s=60.0)
    for key in ("g1", "g2"):
        pacer.sent(key)
        time.sleep(0.001)  # distinct send times
    assert pacer.drawn("g2") and pacer.wait_s() == 0
    assert not pacer.drawn("g1")  # already counted as drawn
    assert not pacer.drawn("nonsense") and not pacer.drawn(None)


def test_only_the_newest_held_frame_is_kept_and_released_once():
    pacer: FramePacer[str] = FramePacer(max_in_flight=1, ack_timeout_s=60.0)
    pacer.sent("g1")
    pacer.hold("frame 2")
    pacer.hold("frame 3")
    assert pacer.release() is None  # the page has not drawn g1 yet
    pacer.drawn("g1")
    assert pacer.release() == "frame 3"
    assert pacer.release() is None


def test_an_unreported_frame_stops_counting_after_the_ack_timeout():
    pacer = FramePacer(max_in_flight=1, ack_timeout_s=0.02)
    pacer.sent("g1")
    assert pacer.wait_s() > 0
    time.sleep(0.03)
    assert pacer.wait_s() == 0


def test_a_sent_frame_drops_any_held_one_and_disabled_pacing_never_waits():
    pacer = FramePacer(max_in_flight=1, ack_timeout_s=60.0)
    pacer.hold("old")
    pacer.sent("g5")
    assert pacer.held is None
    off = FramePacer(enabled=False, max_in_flight=1)
    off.sent("g1")
    assert off.wait_s() == 0
