"""The page's first answers (app.server.index_page): trame's index.html with a preload link for
each style sheet and script the page's state names, so the browser fetches them while the page
connects (nothing else of trame's page changes); and its question to a session manager, told the
websocket beside the page."""

from __future__ import annotations

import json
import re
import urllib.error
import urllib.request

import pytest
from test_app_hostile import app, http_get  # noqa: F401  (the module's app server)

from app.server import index_page
from app.ui import static

INDEX = """<!doctype html>
<html><head>
    <script src="vue.global.js"></script>
    <script type="module" crossorigin src="./assets/index-x.js"></script>
  </head>
  <body><div id="app"></div></body></html>
"""
LINK = re.compile(r'<link rel="preload" as="(style|script)" href="([^"]*)">')


def test_each_style_and_script_gets_a_preload_link_in_the_head_and_the_rest_is_kept(tmp_path):
    index = tmp_path / "index.html"
    index.write_text(INDEX)
    state = {
        "trame__styles": ["a/one.css", ["b/two.css", {"serial": "x"}]],
        "trame__scripts": ["c/three.js", "d/f&g.js"],
    }
    page = index_page.page_html(state, index)
    head, body = page.split("</head>")
    assert LINK.findall(head) == [
        ("style", "a/one.css"),
        ("style", "b/two.css"),
        ("script", "c/three.js"),
        ("script", "d/f&amp;g.js"),  # escaped
    ]
    assert LINK.sub("", page).replace(" ", "").replace("\n", "") == INDEX.replace(" ", "").replace(
        "\n", ""
    )
    assert not LINK.search(body)


def test_the_served_page_preloads_the_widget_libraries_and_its_own_files_each_of_which_answers(
    app,  # noqa: F811
):
    status, headers = http_get(app.url)
    assert status == 200
    cookie = headers["Set-Cookie"].split(";")[0]
    request = urllib.request.Request(app.url)
    with urllib.request.urlopen(request, timeout=30) as response:
        page = response.read().decode()
    links = LINK.findall(page.split("</head>")[0])
    names = [name for _, name in links]
    own = static.module()
    for name in (*own["styles"], *own["scripts"]):
        assert name in names
    assert any(n.endswith("vuetify3.css") for n in names)
    assert any(n.endswith("trame-vtk.js") for n in names)
    assert not any("plotly" in n for n in names)  # loaded after the first frame
    assert "vue.global.js" in page and "index-" in page  # trame's own page around them
    for name in names:
        assert http_get(f"{app.origin}/{name}", {"Cookie": cookie})[0] == 200, name


def post(url: str, headers: dict | None = None) -> tuple[int, dict, bytes]:
    request = urllib.request.Request(url, data=b"{}", headers=headers or {}, method="POST")
    try:
        with urllib.request.urlopen(request, timeout=30) as response:
            return response.status, dict(response.headers), response.read()
    except urllib.error.HTTPError as exc:
        return exc.code, dict(exc.headers), exc.read()


def test_trames_question_to_a_session_manager_is_told_the_pages_own_websocket(app):  # noqa: F811
    """trame's page POSTs to ``paraview/`` at every load (wslink's launcher protocol) and
    connects where the answer says: here, the ``/ws`` beside the page; with the token only."""
    cookie = http_get(app.url)[1]["Set-Cookie"].split(";")[0]
    status, headers, body = post(f"{app.origin}/paraview/", {"Cookie": cookie})
    assert (status, headers["Content-Type"].split(";")[0]) == (200, "application/json")
    assert json.loads(body) == {"sessionURL": "ws://USE_HOST/ws"}
    assert post(f"{app.origin}/paraview/")[0] == 403  # no token: nothing is said
    assert post(f"{app.origin}/other/", {"Cookie": cookie})[0] != 200


def test_the_answer_is_refused_a_path_the_client_would_change_by_lowercasing_it():
    assert index_page.session_manager_answer("/s/ab12") == {"sessionURL": "ws://USE_HOST/s/ab12/ws"}
    with pytest.raises(ValueError, match="lowercase"):
        index_page.session_manager_answer("/s/aB12")


def test_a_link_naming_the_frameworks_connection_settings_is_served_without_them(app):  # noqa: F811
    """trame's page takes ``sessionURL``, ``secret`` and the like from its own address: a link
    naming them (any case) is sent on without them, the app's own settings and the token kept."""
    link = f"{app.url}&sessionURL=ws://evil.example/ws&SECRET=x&pitch_deg=30"

    class Stay(urllib.request.HTTPRedirectHandler):
        def redirect_request(self, *args, **kwargs):
            return None  # see the redirect itself

    opener = urllib.request.build_opener(Stay)
    with pytest.raises(urllib.error.HTTPError) as seen:
        opener.open(link, timeout=30)
    assert seen.value.code == 302
    location = seen.value.headers["Location"]
    assert "pitch_deg=30" in location and "token=" in location
    assert "evil" not in location and "secret" not in location.lower()
    assert http_get(link)[0] == 200  # followed: the page
