"""No module of the library, nor of the app's server (app/server/), over 500 lines unless its
docstring says why: a line of it that starts with "Over 500 lines:" (a module that long mixes
concerns more often than not). The rest of the app is not held to it yet (app/logic/controller.py
is longer)."""

from __future__ import annotations

import ast
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
LIMIT = 500
REASON = "Over 500 lines:"


def oversized(folder: Path) -> list[str]:
    """The modules under ``folder`` longer than LIMIT lines whose docstring gives no reason."""
    found = []
    for path in sorted(folder.rglob("*.py")):
        text = path.read_text(encoding="utf-8")
        if len(text.splitlines()) <= LIMIT:
            continue
        doc = ast.get_docstring(ast.parse(text)) or ""
        if not any(line.strip().startswith(REASON) for line in doc.splitlines()):
            found.append(path.relative_to(folder.parent).as_posix())
    return found


def test_the_rule_finds_a_long_module_without_its_reason_and_accepts_one_with_it(tmp_path):
    pkg = tmp_path / "pkg"
    pkg.mkdir()
    body = "x = 1\n" * LIMIT
    (pkg / "long.py").write_text('"""A long module."""\n' + body)
    (pkg / "said.py").write_text(f'"""A long module.\n\n{REASON} one table.\n"""\n' + body)
    (pkg / "short.py").write_text('"""Short."""\n' + "x = 1\n" * (LIMIT - 1))
    assert oversized(pkg) == ["pkg/long.py"]


def test_no_module_of_simcore_is_over_500_lines_without_saying_why():
    assert oversized(ROOT / "simcore") == []


def test_no_module_of_the_app_server_is_over_500_lines_without_saying_why():
    assert oversized(ROOT / "app" / "server") == []
