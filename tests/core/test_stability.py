"""Stability at the extremes (issue 25): every value inside a key's documented range runs, or is
refused before running with one message naming the key."""

import pytest

from simcore.scene import Scene, SceneError, key_reference, with_overrides

L1 = "1 25544U 98067A   08264.51782528 -.00002182  00000-0 -11606-4 0  2927"
L2 = "2 25544  51.6416 247.4627 0006703 130.5360 325.0288 15.72125391563537"


def _with_checksum(line68: str) -> str:
    return line68 + str((sum(int(c) for c in line68 if c.isdigit()) + line68.count("-")) % 10)


def _range(key: str) -> str:
    return next(r["valid"] for r in key_reference() if r["key"] == key)


# -- documented ranges are the real ones --------------------------------------------------------
def test_the_whole_filter_range_runs_with_a_sun():
    top = float(_range("receive.filter_width_m").split(",")[1].split("]")[0])
    scene = with_overrides(
        Scene(), {"sun.mode": "manual", "receive.filter_width_m": top, "pixels": 4}
    )
    assert scene.receive.filter_width_m == top


def test_a_filter_wider_than_the_range_is_refused_naming_the_key():
    with pytest.raises(SceneError, match=r"receive\.filter_width_m .*valid range \(0, 3e-07\]"):
        with_overrides(Scene(), {"receive.filter_width_m": 5e-7})


@pytest.mark.parametrize("size_m", [1e-4, 5e-4, 9.99e-4])
def test_a_target_size_between_0_and_1_mm_is_refused_by_its_range(size_m):
    assert _range("target.size_m").startswith("0 or [0.001,")
    with pytest.raises(SceneError, match=r"target\.size_m .*0 or \[0\.001, 10000\] m"):
        with_overrides(Scene(), {"target.size_m": size_m})


@pytest.mark.parametrize("size_m", [0.0, 1e-3, 1e4])
def test_a_target_size_of_0_or_inside_the_range_is_valid(size_m):
    assert with_overrides(Scene(), {"target.size_m": size_m}).target.size_m == size_m


# -- epochs and TLEs: one clear message ---------------------------------------------------------
def test_an_epoch_before_year_1_in_utc_is_one_clear_message():
    with pytest.raises(SceneError, match=r"orbit\.epoch_utc .*years 1 to 9999"):
        with_overrides(Scene(), {"orbit.epoch_utc": "0001-01-01T00:00:00+01:00"})


def test_a_huge_time_after_a_late_epoch_is_refused_not_overflowed():
    with pytest.raises(SceneError, match=r"orbit\.time_s"):
        with_overrides(Scene(), {"orbit.epoch_utc": "2050-12-30T00:00:00Z", "orbit.time_s": 1e9})


def test_a_non_ascii_digit_in_a_tle_is_one_clear_message():
    bad = L1[:68] + "\u00b2"  # a superscript two: str.isdigit() says True, int() fails
    with pytest.raises(SceneError, match=r"orbit\.target_tle: line 1 .*not ASCII"):
        with_overrides(Scene(), {"orbit.target_tle": f"{bad}\n{L2}"})
    arabic = L1[:60] + "\u0663" + L1[61:]
    with pytest.raises(SceneError, match=r"orbit\.target_tle: line 1"):
        with_overrides(Scene(), {"orbit.target_tle": f"{arabic}\n{L2}"})


def test_a_tle_at_99_rev_per_day_says_its_orbit_lies_inside_the_earth():
    fast = _with_checksum(L2[:52] + "99.72125391563" + L2[66:68])
    assert len(fast) == 69
    with pytest.raises(SceneError, match=r"orbit\.target_tle: .*inside the Earth.*99\.72 rev/day"):
        with_overrides(Scene(), {"orbit.target_tle": f"{L1}\n{fast}"})


def test_the_iss_tle_still_reads():
    scene = with_overrides(Scene(), {"orbit.target_tle": f"{L1}\n{L2}"})
    assert scene.orbit.target_tle.startswith("1 25544")
