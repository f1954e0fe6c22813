"""Browser-test fixtures: the real app server in a subprocess and Debian's headless Chromium.

The tests fail (never skip) when Chromium is missing: the README's `make test` installs it.
"""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from support.launch import CHROMIUM_ARGS, CHROMIUM_PATH, app_server, chromium_missing_message

ARTIFACTS = Path(__file__).resolve().parents[2] / "test-artifacts"


@pytest.fixture(scope="session")
def browser_type_launch_args(browser_type_launch_args):
    """pytest-playwright's launch options, pointed at Debian's Chromium (never a downloaded one)."""
    problem = chromium_missing_message()
    if problem:
        pytest.fail(problem, pytrace=False)
    return {**browser_type_launch_args, "executable_path": CHROMIUM_PATH, "args": CHROMIUM_ARGS}


@pytest.fixture(scope="session")
def browser_context_args(browser_context_args):
    return {**browser_context_args, "viewport": {"width": 1600, "height": 1000}}


# every page of a test's context keeps its errors (uncaught, unhandled rejections and
# console.error: Vue's own reports) in window.lmapdErrors, the last MAX_ERRORS of them:
# support.launch.page_report shows them when a wait runs out
RECORD_ERRORS = """(() => {
  const MAX_ERRORS = 20;
  const keep = (what) => {
    const errors = (window.lmapdErrors = window.lmapdErrors || []);
    errors.push(`${(performance.now() / 1000).toFixed(2)} s ${String(what).slice(0, 400)}`);
    errors.splice(0, Math.max(0, errors.length - MAX_ERRORS));
  };
  window.addEventListener('error', (e) => keep(e.error ? e.error.stack || e.error : e.message));
  window.addEventListener('unhandledrejection', (e) => keep(`unhandled: ${e.reason}`));
  const error = console.error;
  console.error = (...args) => { keep(args.map(String).join(' ')); error.apply(console, args); };
})();"""


@pytest.fixture
def context(context):
    """pytest-playwright's context, its pages recording their errors (``RECORD_ERRORS``)."""
    context.add_init_script(RECORD_ERRORS)
    return context


@pytest.fixture(scope="session")
def artifacts_dir() -> Path:
    """test-artifacts/, or test-artifacts/<worker>/ on a pytest-xdist worker (``make test`` runs
    two): each worker starts its own servers, which would otherwise write the same log files."""
    worker = os.environ.get("PYTEST_XDIST_WORKER")
    path = ARTIFACTS / worker if worker else ARTIFACTS
    path.mkdir(parents=True, exist_ok=True)
    return path


@pytest.fixture(scope="session")
def app_url(artifacts_dir):
    """The URL of a freshly started app server (paper scene) on a free 127.0.0.1 port."""
    with app_server(log_path=artifacts_dir / "app-server.log") as url:
        yield url
