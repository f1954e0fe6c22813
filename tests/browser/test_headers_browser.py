"""The app under its own headers (app.server.headers) in a real Chromium: the page, in --shared
mode and behind the launcher, draws its frame with no Content-Security-Policy violation (the
browser reports each one as a ``securitypolicyviolation`` event); a page on another origin
that frames the app gets no app in its frame; a page from another port of 127.0.0.1 that
navigates the teacher's tab to the door starts no session (app.server.launcher)."""

from __future__ import annotations

import http.server
import threading
import urllib.parse

import psutil
import pytest
from support.launch import app_process, free_port, wait_first_frame, wait_settled

pytestmark = pytest.mark.browser

# every CSP violation of a page, kept where the test reads it (installed before any script)
RECORD_VIOLATIONS = """(() => {
  window.lmapdViolations = [];
  document.addEventListener('securitypolicyviolation', (e) => {
    window.lmapdViolations.push(`${e.violatedDirective} ${e.blockedURI} ${e.sample}`);
  });
})();"""

SMALL = "&pixels=32"


def serve_page(body: str) -> tuple[http.server.ThreadingHTTPServer, str]:
    """A page of another origin (another port of 127.0.0.1) serving ``body`` at ``/``."""

    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # http.server's name
            data = body.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(data)))
            self.end_headers()
            self.wfile.write(data)

        def log_message(self, *args):
            pass

    port = free_port()
    server = http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{port}/"


def violations(page) -> list[str]:
    return page.evaluate("() => window.lmapdViolations || []")


def test_the_shared_app_runs_under_its_headers_and_a_foreign_frame_gets_no_app(page, app_url):
    page.context.add_init_script(RECORD_VIOLATIONS)
    response = page.goto(app_url + SMALL)
    headers = response.headers
    policy = headers["content-security-policy"]
    assert "frame-ancestors 'none'" in policy and "'unsafe-inline'" not in policy.split(";")[1]
    assert headers["x-content-type-options"] == "nosniff"
    assert headers["referrer-policy"] == "no-referrer"
    assert headers["cache-control"] == "no-store"
    wait_first_frame(page)
    wait_settled(page)  # the charts' library too, loaded after the first frame
    assert violations(page) == []
    server, foreign = serve_page(f"<!doctype html><iframe src='{app_url}'></iframe>")
    try:
        framer = page.context.new_page()
        framer.goto(foreign)
        frame = framer.frame_locator("iframe")
        framer.wait_for_timeout(500)  # a framed app would be loading its scripts by now
        assert frame.locator("#app").count() == 0  # the browser showed its error page instead
        assert len(framer.frames) == 2
        assert framer.frames[1].url in ("", "about:blank") or "chrome-error" in framer.frames[1].url
    finally:
        server.shutdown()


def test_behind_the_launcher_the_door_and_the_session_run_under_their_headers(page, artifacts_dir):
    """The door's streamed page moves the tab by its nonce'd script; the session's page draws;
    a page from another port of 127.0.0.1 that navigates the tab to the door (the browser sends
    the token's cookie: same site) starts no session."""
    log_path = artifacts_dir / "app-server-headers.log"
    options = ("--max-sessions", "3", "--no-spare")
    with app_process(log_path=log_path, sessions=True, app_args=options) as running:
        page.context.add_init_script(RECORD_VIOLATIONS)
        page.goto(running.url + SMALL, wait_until="commit")
        page.wait_for_url(lambda url: "/s/" in url or "token" not in url, timeout=120_000)
        wait_first_frame(page)
        wait_settled(page)
        assert violations(page) == []
        n_before = len(psutil.Process(running.pid).children(recursive=True))
        door = urllib.parse.urlsplit(running.url)._replace(query="").geturl()
        server, foreign = serve_page(
            f"<!doctype html><a id='go' href='{door}'>open</a>"
            "<script>document.getElementById('go').click()</script>"
        )
        try:
            other = page.context.new_page()
            other.goto(foreign, wait_until="commit")
            other.wait_for_url(lambda url: url.startswith(door), timeout=30_000)
            other.wait_for_load_state()
            assert "Open the address that lmapd app printed" in other.content()
        finally:
            server.shutdown()
        assert len(psutil.Process(running.pid).children(recursive=True)) == n_before
