"""The documented reverse proxy (docs/examples/nginx-lmapd.conf) in front of the launcher: over
HTTPS a tab opens its session, loads its page and speaks on its websocket, and a foreign page's
websocket is refused. The launcher runs in this process with stand-in sessions; nginx is started
from the documented file with only its name, ports and certificate put in."""

from __future__ import annotations

import asyncio
import contextlib
import json
import re
import shutil
import socket
import ssl
import subprocess
import time
from pathlib import Path

import aiohttp
import pytest
from aiohttp import web
from support.ci import skip_unless_ci
from test_app_launcher import FAKE, MOVE, NAVIGATION, TOKEN, caps, run

from app.server import connections
from app.server import launcher as lau

CONFIG = Path(__file__).resolve().parents[2] / "docs" / "examples" / "nginx-lmapd.conf"
WAIT_S = 60.0


def fake_command(*_):
    import sys

    return [sys.executable, str(FAKE)]


def free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def nginx_config(folder: Path, proxy_port: int, app_port: int) -> Path:
    """The documented file with this test's name, ports and certificate, in a whole nginx
    configuration that runs in ``folder``."""
    cert, key = folder / "cert.pem", folder / "key.pem"
    subprocess.run(
        ["openssl", "req", "-x509", "-newkey", "rsa:2048", "-nodes", "-days", "1"]
        + ["-subj", "/CN=localhost", "-keyout", str(key), "-out", str(cert)],
        check=True,
        capture_output=True,
    )
    text = CONFIG.read_text()
    for old, new in (
        ("listen 443 ssl;", f"listen 127.0.0.1:{proxy_port} ssl;"),
        ("server_name lidar.example.org;", "server_name localhost;"),
        ("/etc/ssl/lidar.example.org/fullchain.pem", str(cert)),
        ("/etc/ssl/lidar.example.org/privkey.pem", str(key)),
        ("http://127.0.0.1:8080;", f"http://127.0.0.1:{app_port};"),
    ):
        assert text.count(old) == 1, old  # the documented file still says this
        text = text.replace(old, new)
    (folder / "lmapd.conf").write_text(text)
    temp = "".join(
        f"{kind}_temp_path {folder / kind};\n" for kind in ("client_body", "proxy", "fastcgi")
    )
    temp += "".join(f"{kind}_temp_path {folder / kind};\n" for kind in ("uwsgi", "scgi"))
    main = folder / "nginx.conf"
    main.write_text(
        f"daemon off;\nworker_processes 1;\npid {folder / 'nginx.pid'};\n"
        f"error_log {folder / 'error.log'};\nevents {{ worker_connections 128; }}\n"
        f"http {{\naccess_log off;\n{temp}include {folder / 'lmapd.conf'};\n}}\n"
    )
    return main


@contextlib.contextmanager
def nginx(config: Path, port: int):
    proc = subprocess.Popen(
        ["nginx", "-p", str(config.parent), "-c", str(config), "-e", str(config.parent / "e.log")],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
    )
    try:
        deadline = time.monotonic() + WAIT_S
        while True:
            assert proc.poll() is None, proc.stderr.read().decode()
            with contextlib.suppress(OSError), socket.create_connection(("127.0.0.1", port), 1):
                break
            assert time.monotonic() < deadline, "nginx did not listen"
            time.sleep(0.1)
        yield
    finally:
        proc.terminate()
        proc.wait(timeout=WAIT_S)


def test_the_documented_nginx_proxy_serves_a_session_over_https(tmp_path):
    if not (shutil.which("nginx") and shutil.which("openssl")):
        skip_unless_ci("needs nginx and openssl (.ci/run installs them)")
    proxy_port = free_port()
    public = f"https://localhost:{proxy_port}"

    async def body():
        launcher = lau.Launcher(
            TOKEN, "127.0.0.1", caps(spare=False), command=fake_command, origins=(public,)
        )
        runner = web.AppRunner(launcher.web_app(), access_log=None)
        await runner.setup()
        server, sweeper, app_port = await connections.listen(runner, launcher.guard, "127.0.0.1", 0)
        tls = ssl.create_default_context()
        tls.check_hostname, tls.verify_mode = False, ssl.CERT_NONE
        try:
            with nginx(nginx_config(tmp_path, proxy_port, app_port), proxy_port):
                jar = aiohttp.DummyCookieJar()
                async with aiohttp.ClientSession(cookie_jar=jar) as client:
                    door = f"{public}/?token={TOKEN}&pixels=32"
                    async with client.get(door, headers=NAVIGATION, ssl=tls) as answer:
                        assert answer.status == 200
                        cookies = {k: m.value for k, m in answer.cookies.items()}
                        location = json.loads(MOVE.search(await answer.text())[1])
                    path = location.split("?")[0]
                    own = {"Cookie": "; ".join(f"{k}={v}" for k, v in cookies.items())}
                    async with client.get(f"{public}{path}", headers=own, ssl=tls) as answer:
                        assert answer.status == 200 and "token ok" in await answer.text()
                    ws_url = f"wss://localhost:{proxy_port}{path}ws"
                    with pytest.raises(aiohttp.WSServerHandshakeError) as refused:
                        await client.ws_connect(
                            ws_url, headers={"Origin": "https://evil.example", **own}, ssl=tls
                        )
                    assert refused.value.status == 403
                    ws = await client.ws_connect(ws_url, headers={"Origin": public, **own}, ssl=tls)
                    await ws.send_bytes(b"through the proxy")
                    echo = await asyncio.wait_for(ws.receive(), WAIT_S)
                    await ws.close()
                    return echo.data
        finally:
            await connections.stop_listening(server, sweeper)
            await runner.cleanup()

    assert run(body) == b"through the proxy"
    assert re.search(r"\[(emerg|alert|crit)\]", (tmp_path / "error.log").read_text()) is None
