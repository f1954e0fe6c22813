"""The real launcher (app.server.launcher) with stand-in sessions (tests/support/fake_session.py),
run as ``lmapd app`` runs it (the open-file limit raised, aiohttp's logs made short): for tests that
need the launcher in a process of its own, such as under a low open-file limit.

    python tests/support/fake_launcher.py [--guard-idle-s S] [--per-address N]

It prints ``lmapd-sim app: http://127.0.0.1:PORT/?token=TOKEN`` once it listens and serves until
SIGTERM or SIGINT.
"""

from __future__ import annotations

import argparse
import asyncio
import logging
import secrets
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[2]))

from app.server import connections, launcher

FAKE_SESSION = Path(__file__).resolve().parent / "fake_session.py"


def main() -> int:
    parser = argparse.ArgumentParser()
    parser.add_argument("--guard-idle-s", type=float, default=connections.IDLE_S)
    parser.add_argument("--per-address", type=int, default=connections.PER_ADDRESS)
    args = parser.parse_args()
    logging.basicConfig(level=logging.WARNING, format="%(levelname)s %(name)s: %(message)s")
    connections.shorten_server_logs()
    connections.raise_open_file_limit()
    token = secrets.token_urlsafe(32)
    caps = launcher.Caps(max_sessions=4, memory_cap_bytes=2**40, spare=False)
    door = launcher.Launcher(
        token, "127.0.0.1", caps, command=lambda *_: [sys.executable, str(FAKE_SESSION)]
    )
    door.guard = connections.ConnectionGuard(args.guard_idle_s, args.per_address)

    def announce(port: int) -> None:
        print(f"lmapd-sim app: http://127.0.0.1:{port}/?token={token}", flush=True)

    try:
        asyncio.run(launcher.serve(door, "127.0.0.1", 0, announce))
    except KeyboardInterrupt:
        pass
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
