"""``lmapd keys``: every scene key with its unit, default, valid range and meaning.

lmapd keys [--markdown]
"""

from __future__ import annotations

import argparse
from typing import Any

from .common import say


def add_parser(subparsers: Any) -> argparse.ArgumentParser:
    """Register the ``keys`` subcommand on ``subparsers`` (from ``add_subparsers``)."""
    keys = subparsers.add_parser(
        "keys", help="list every scene key with its unit, default and range"
    )
    keys.add_argument("--markdown", action="store_true", help="as a Markdown table")
    keys.set_defaults(func=run_cli)
    return keys


def run_cli(args: argparse.Namespace) -> int:
    """Print the key reference (a table, or Markdown with ``--markdown``); exit status 0."""
    from ..scene import key_reference  # noqa: PLC0415  (the scene module only: no numpy)

    rows = key_reference()
    if args.markdown:
        say("| key | unit | default | valid | meaning |")
        say("|---|---|---|---|---|")
        for r in rows:
            say(f"| `{r['key']}` | {r['unit']} | {r['default']} | {r['valid']} | {r['doc']} |")
    else:
        width = max(len(r["key"]) for r in rows)
        for r in rows:
            cells = f"{r['unit']:<4} {r['default']:<22} {r['valid']:<28}"
            say(f"{r['key']:<{width}}  {cells} {r['doc']}")
    return 0
