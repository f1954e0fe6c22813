"""The physics page's sections in the page itself: a lesson card's "Read more" opens the section
of docs/physics.md it names in a dialog (the page serves no files of its own), a child of the
app's logic.

The section is the heading that holds the anchor (``<a id="eq-29"></a>``) and what follows it up
to the next heading of its level or above, rendered as HTML by ``markdown`` where it is installed
(the docs' own dependency), else shown as its text. An installed wheel carries no docs/: the card
then names the section, as before, without a link (``available`` is False).
"""

from __future__ import annotations

import html
import re
from functools import lru_cache
from pathlib import Path
from typing import Any

PHYSICS_MD = Path(__file__).resolve().parents[2] / "docs" / "physics.md"
ANCHOR = re.compile(r"[a-z0-9][a-z0-9-]{0,63}")
HEADING = re.compile(r"^(#{1,6})\s")


@lru_cache(maxsize=1)
def _lines(path: Path = PHYSICS_MD) -> tuple[str, ...]:
    return tuple(path.read_text(encoding="utf-8").splitlines()) if path.is_file() else ()


def section_text(anchor: str, path: Path = PHYSICS_MD) -> tuple[str, str] | None:
    """(title, markdown) of the section of ``path`` whose heading holds ``anchor``; None if
    there is none."""
    lines = _lines(path)
    tag = f'<a id="{anchor}"></a>'
    start = next((i for i, line in enumerate(lines) if tag in line), None)
    if start is None:
        return None
    level = HEADING.match(lines[start])
    depth = len(level.group(1)) if level else 6
    end = len(lines)
    for i in range(start + 1, len(lines)):
        m = HEADING.match(lines[i])
        if m and len(m.group(1)) <= depth:
            end = i
            break
    title = re.sub(r"<a id=\"[^\"]*\"></a>", "", lines[start]).lstrip("#").strip()
    return title, "\n".join(lines[start + 1 : end]).strip()


def section_html(markdown_text: str) -> str:
    """The section as HTML (``markdown`` with tables), or its escaped text."""
    try:
        import markdown  # noqa: PLC0415 (the docs' dependency: optional here)
    except ImportError:
        return f"<pre style='white-space: pre-wrap'>{html.escape(markdown_text)}</pre>"
    return markdown.markdown(markdown_text, extensions=["tables", "fenced_code"])


class PhysicsPage:
    """``physics_section`` on a trame state: the section shown (None: the dialog is closed), and
    ``physics_available``: whether this installation has the physics page."""

    def __init__(self, state, path: Path = PHYSICS_MD):
        self.state = state
        self.path = path
        state.physics_section = None
        state.physics_available = bool(_lines(path))

    def open(self, reference: Any = None, *_: Any, **__: Any) -> None:
        """Show the section ``reference`` names (``docs/physics.md#eq-29`` or ``eq-29``; from
        the page: anything at all); an unknown one gives a message. Never raises."""
        anchor = str(reference).rsplit("#", 1)[-1] if isinstance(reference, str) else ""
        found = section_text(anchor, self.path) if ANCHOR.fullmatch(anchor) else None
        if found is None:
            self.state.input_message = "Physics page: no such section"
            return
        title, text = found
        self.state.physics_section = {
            "anchor": anchor,
            "title": title,
            "html": section_html(text),
        }

    def close(self, *_: Any, **__: Any) -> None:
        self.state.physics_section = None
