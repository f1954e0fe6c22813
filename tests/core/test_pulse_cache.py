"""The pulse's timing marks on disk: the same bits as found by scipy.optimize, rebuilt when corrupt,
skipped when unwritable, and read without importing scipy.optimize."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path

import pytest

from simcore import pulse
from simcore.cache import CACHE_ENV

ROOT = Path(__file__).resolve().parents[2]
PAPER_PULSE = (5e-9, pulse.A_FWHM, 120e6)  # tau [s], Eq. 1's a, bandwidth [Hz]


@pytest.fixture
def cache(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, str(tmp_path / "cache"))
    pulse.pulse_shape.cache_clear()
    yield tmp_path / "cache" / "pulses"
    pulse.pulse_shape.cache_clear()


def searched_marks(tau_s, a, bandwidth_hz):
    """The marks found afresh with scipy.optimize, no cache involved."""
    sigma = pulse.band_limit_sigma_s(bandwidth_hz)
    t = pulse.table_times_s(tau_s, a, sigma)
    return pulse.timing_marks(t, pulse.filtered_pulse_w(t, 1.0, tau_s, a, sigma), tau_s, a, sigma)


def marks_of(shape):
    return (shape.t_peak_s, shape.peak_w_per_j, shape.t_half_s)


def test_a_cached_pulse_has_the_marks_of_a_fresh_search_to_the_last_bit(cache):
    cold = marks_of(pulse.pulse_shape(*PAPER_PULSE))
    assert len(list(cache.glob("*.json"))) == 1
    pulse.pulse_shape.cache_clear()
    warm = marks_of(pulse.pulse_shape(*PAPER_PULSE))
    assert [m.hex() for m in warm] == [m.hex() for m in cold]
    assert [m.hex() for m in warm] == [float(m).hex() for m in searched_marks(*PAPER_PULSE)]


def test_another_pulse_gets_another_entry(cache):
    pulse.pulse_shape(*PAPER_PULSE)
    other = pulse.pulse_shape(4e-9, pulse.A_FWHM, 120e6)
    assert len(list(cache.glob("*.json"))) == 2
    assert other.t_peak_s < pulse.pulse_shape(*PAPER_PULSE).t_peak_s


@pytest.mark.parametrize(
    "damage",
    [
        "",
        "{not json",
        '{"t_peak_s": "0x1p-29"}',
        '{"t_peak_s": 1, "peak_w_per_j": 2, "t_half_s": 3}',
    ],
)
def test_a_corrupt_entry_is_rebuilt_with_a_warning(cache, damage):
    good = marks_of(pulse.pulse_shape(*PAPER_PULSE))
    (entry,) = cache.glob("*.json")
    entry.write_text(damage)
    pulse.pulse_shape.cache_clear()
    with pytest.warns(UserWarning, match="corrupt"):
        again = marks_of(pulse.pulse_shape(*PAPER_PULSE))
    assert again == good
    assert json.loads(entry.read_text())["t_half_s"] == good[2].hex()


def test_inconsistent_marks_are_refused(cache):
    pulse.pulse_shape(*PAPER_PULSE)
    (entry,) = cache.glob("*.json")
    marks = json.loads(entry.read_text())
    marks["t_half_s"], marks["t_peak_s"] = marks["t_peak_s"], marks["t_half_s"]
    entry.write_text(json.dumps(marks))
    pulse.pulse_shape.cache_clear()
    with pytest.warns(UserWarning, match="inconsistent"):
        pulse.pulse_shape(*PAPER_PULSE)


def test_an_unwritable_cache_warns_and_the_marks_are_still_found(tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv(CACHE_ENV, str(blocker / "cache"))
    pulse.pulse_shape.cache_clear()
    with pytest.warns(UserWarning, match="not writable"):
        shape = pulse.pulse_shape(*PAPER_PULSE)
    pulse.pulse_shape.cache_clear()
    assert [m.hex() for m in marks_of(shape)] == [
        float(m).hex() for m in searched_marks(*PAPER_PULSE)
    ]


def test_off_disables_the_cache(tmp_path, monkeypatch):
    monkeypatch.setenv(CACHE_ENV, "off")
    pulse.pulse_shape.cache_clear()
    pulse.pulse_shape(*PAPER_PULSE)
    pulse.pulse_shape.cache_clear()
    assert not any(tmp_path.iterdir())


PROBE = """
import json, sys
import simcore
from simcore.pulse import scene_pulse_shape
scene_pulse_shape(simcore.load_scene())
print(json.dumps("scipy.optimize" in sys.modules))
"""


def test_a_cached_pulse_is_tabulated_without_importing_scipy_optimize(cache):
    env_cache = cache.parent
    runs = [
        subprocess.run(
            [sys.executable, "-c", PROBE],
            capture_output=True,
            text=True,
            check=True,
            cwd=ROOT,
            env={**os.environ, CACHE_ENV: str(env_cache)},
        )
        for _ in range(2)
    ]
    assert [json.loads(r.stdout) for r in runs] == [True, False]  # searched once, then read
