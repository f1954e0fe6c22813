"""Shared fixtures: small synthetic targets written as real mesh files, and a fast base scene."""

from __future__ import annotations

import os

import pytest
from support.mesh_files import write_plates

import simcore
from simcore.cache import cache_dir

# The compiled kernels' on-disk cache (numba) stays the user's, shared by the test processes and
# the commands they start: under the fresh per-session cache folder below, every test process
# (each pytest-xdist worker) and the first command each starts would compile every kernel again
# (15-40 s each here). numba checks its cached code against the source, so nothing stale runs.
# Set before numba is imported (simcore loads it on a frame's first use).
if "NUMBA_CACHE_DIR" not in os.environ and cache_dir() is not None:
    os.environ["NUMBA_CACHE_DIR"] = str(cache_dir() / "numba")

# The slowest files, run first: `make test` gives each file to one of two workers as it frees
# up, so a long file picked up last kept one worker busy alone for minutes. pytest-xdist 3.8
# reorders files by their number of tests unless told not to (the Makefile passes
# --no-loadscope-reorder): without it the one-test soak ran last. At the start each worker takes
# two files (the first and the third to one of them), so the soak and the sessions' browser
# test, the two that load the machine most, run one after the other on one worker. Seconds per
# file (junit, two full runs on this project's 2-core machine, 2026-11-26).
SLOW_FIRST = (
    "tests/browser/test_soak.py",  # 89-124 s
    "tests/app/test_app_reliability.py",  # 52-87 s
    "tests/browser/test_sessions_browser.py",  # 92-98 s
    "tests/browser/test_lessons_browser.py",  # 44-49 s
    "tests/app/test_app_launcher.py",  # 43-44 s
    "tests/browser/test_classroom_browser.py",  # 37-48 s
    "tests/core/test_extremes.py",  # 37-42 s
    "tests/browser/test_a11y_browser.py",  # 37-43 s
    "tests/core/test_design.py",  # 34-38 s
    "tests/cli/test_reproduce.py",  # 30-32 s
    "tests/browser/test_screens_browser.py",  # 28-32 s
)


def pytest_collection_modifyitems(config, items):
    """Put the tests of SLOW_FIRST's files first, in its order; the rest keep theirs."""
    rank = {path: i for i, path in enumerate(SLOW_FIRST)}
    items.sort(key=lambda item: rank.get(item.nodeid.split("::")[0], len(rank)))


@pytest.fixture
def plate_scene(tmp_path):
    """A 4 m Lambertian plate square to the boresight (its smallest extent along the line of sight),
    64 x 64 pixels, 1 sub-ray, 1 m per unit."""

    def make(size_m=4.0, tilt_deg=0.0, plates=None, **overrides):
        mesh = write_plates(tmp_path / "plate.obj", plates or [(size_m, 0.0, tilt_deg)])
        base = {
            "target.mesh": mesh,
            "target.scale_m_per_unit": 1.0,
            "target.materials": {"*": "lambertian"},
            "pixels": 64,
            "fidelity.subrays": 1,
        }
        base.update(overrides)
        return simcore.with_overrides(simcore.Scene(), base)

    return make


@pytest.fixture(autouse=True, scope="session")
def _target_cache(tmp_path_factory):
    """The tests' on-disk target cache is their own (fresh each session, never the user's)."""
    os.environ["LMAPD_CACHE_DIR"] = str(tmp_path_factory.mktemp("lmapd-cache"))
    yield
