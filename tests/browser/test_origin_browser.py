"""A page served from another origin (another port of 127.0.0.1) cannot open the app's websocket,
not even with the access token in its address and the app's cookie in the browser; the app's own
page, opened from the printed address, connects."""

from __future__ import annotations

import http.server
import threading
from urllib.parse import urlsplit

import pytest
from support.launch import free_port, wait_first_frame

pytestmark = pytest.mark.browser

FOREIGN_PAGE = """<!doctype html><html><body><script>
window.results = [];
function attempt(url) {
  return new Promise((resolve) => {
    const ws = new WebSocket(url);
    ws.onopen = () => { resolve('open'); ws.close(); };
    ws.onerror = () => resolve('error');
    ws.onclose = () => resolve('closed');
  });
}
window.run = async (urls) => {
  for (const url of urls) { window.results.push(await attempt(url)); }
  return window.results;
};
</script></body></html>"""


def serve_foreign_page() -> tuple[http.server.ThreadingHTTPServer, str]:
    class Handler(http.server.BaseHTTPRequestHandler):
        def do_GET(self):  # http.server's name
            body = FOREIGN_PAGE.encode()
            self.send_response(200)
            self.send_header("Content-Type", "text/html")
            self.send_header("Content-Length", str(len(body)))
            self.end_headers()
            self.wfile.write(body)

        def log_message(self, *args):
            pass

    port = free_port()
    server = http.server.ThreadingHTTPServer(("127.0.0.1", port), Handler)
    threading.Thread(target=server.serve_forever, daemon=True).start()
    return server, f"http://127.0.0.1:{port}/"


def test_a_page_from_another_origin_cannot_connect(page, app_url):
    page.goto(app_url)  # the app's own page: connects (and the browser now holds its cookie)
    wait_first_frame(page)
    parts = urlsplit(app_url)
    ws = f"ws://{parts.netloc}/ws"
    server, foreign_url = serve_foreign_page()
    try:
        other = page.context.new_page()
        other.goto(foreign_url)
        results = other.evaluate("(urls) => window.run(urls)", [ws, f"{ws}?{parts.query}"])
    finally:
        server.shutdown()
    assert results == ["error", "error"]
    assert page.evaluate("() => window.trame.state.get('n_points')") > 0
