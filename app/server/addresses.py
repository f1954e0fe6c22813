"""What the server prints and how trame is started: the address to open (with this launch's
token), this machine's network addresses on a wildcard host, the warning off loopback, a reverse
proxy's addresses, and trame's own command-line options."""

from __future__ import annotations

from app.server import door

LOOPBACK_HOSTS = door.LOOPBACK_NAMES


def trame_arguments(host: str, port: int, token: str) -> list[str]:
    """The options the trame server is started with: no browser, no idle time-out, this launch's
    token as its key (never the framework's public default). ``--authKey=TOKEN`` in one word: a
    URL-safe token begins with "-" one time in 64, and would be read as an option."""
    return ["--host", host, "--port", str(port), "--server", "--timeout", "0", f"--authKey={token}"]


def app_address(host: str, port: int, token: str) -> str:
    """The address to open: the page with this launch's access token."""
    name = f"[{host}]" if ":" in host else host
    return f"http://{name}:{port}/?token={token}"


def lan_addresses(host: str) -> list[str]:
    """The addresses other machines can open when the server listens on every interface (``host``
    0.0.0.0 or ::): this machine's IPv4 addresses (and global IPv6 ones for ::), loopback and
    link-local ones left out."""
    if host not in door.WILDCARD_HOSTS:
        return []
    import ipaddress  # noqa: PLC0415  (only on a wildcard host)
    import socket  # noqa: PLC0415

    import psutil  # noqa: PLC0415

    families = (socket.AF_INET,) if host == "0.0.0.0" else (socket.AF_INET, socket.AF_INET6)
    found = []
    for addrs in psutil.net_if_addrs().values():
        for addr in addrs:
            if addr.family not in families:
                continue
            try:
                ip = ipaddress.ip_address(addr.address.split("%")[0])
            except ValueError:
                continue
            if ip.is_loopback or ip.is_link_local or ip.is_unspecified or ip.is_multicast:
                continue
            if str(ip) not in found:
                found.append(str(ip))
    return found


def start_message(host: str, port: int, token: str, lan: list[str] | None = None) -> list[str]:
    """What the server prints once it listens: the address to open (on one line, with the access
    token), and a warning if other machines can reach it (a --host other than loopback). On a
    wildcard host (0.0.0.0) the first address is this machine's loopback one, then one line for
    each of its LAN addresses (``lan``: found by :func:`lan_addresses` if None), which are what
    other machines open."""
    if host in door.WILDCARD_HOSTS:
        lan = lan_addresses(host) if lan is None else lan
        lines = [f"lmapd-sim app: {app_address('127.0.0.1', port, token)}  (Ctrl+C stops it)"]
        lines += [f"lmapd-sim app: on the network: {app_address(ip, port, token)}" for ip in lan]
        if not lan:
            lines.append("lmapd-sim app: no network address found (only this machine can open it)")
    else:
        lines = [f"lmapd-sim app: {app_address(host, port, token)}  (Ctrl+C stops it)"]
    if host not in LOOPBACK_HOSTS:
        lines.append(
            f"lmapd-sim app: warning: listening on {host}, not only on this machine: anyone who "
            "can reach this port and has the address above (its token) can drive the simulator "
            "and upload meshes"
        )
    return lines


def public_lines(origins: tuple[str, ...], token: str) -> list[str]:
    """The addresses a reverse proxy serves the app at, each with the token, to print."""
    lines = []
    for url in origins:
        origin = door.normal_origin(url)
        if origin is None:
            lines.append(f"lmapd-sim app: warning: --public-url {url!r} is no http(s) address")
            continue
        base = url.strip().rstrip("/")
        lines.append(f"lmapd-sim app: through the proxy: {base}/?token={token}")
    return lines
