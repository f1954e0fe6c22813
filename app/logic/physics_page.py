"""A lesson card's "Read more", in a dialog of the page itself, a child of the app's logic.

"Read more" shows the lesson's own text for the app's readers (``Lesson.read_more``: what the
equation says in words, then the equation), with its maths drawn: each ``$...$`` (inline) and
``$$...$$`` (display) of the Markdown is turned into MathML by ``latex2mathml`` (pure Python, on
the server: the page gets MathML, which Chromium, Firefox and Safari draw natively, with no
script, no font file and no network; KaTeX would have added 300 kB of script and fonts to serve,
for the few formulas a card needs), the rest by ``markdown``.

Below the text, the full derivation: a link to the physics page of the documentation site where
one is configured (``LMAPD_DOCS_URL``, the address the docs were published at, e.g. by
``mkdocs build``), else the section of docs/physics.md itself, rendered the same way in the
dialog. An installed wheel carries no docs/: the full section is then not offered
(``physics_available`` is False).
"""

from __future__ import annotations

import html
import os
import re
from functools import lru_cache
from pathlib import Path
from typing import Any

PHYSICS_MD = Path(__file__).resolve().parents[2] / "docs" / "physics.md"
ANCHOR = re.compile(r"[a-z0-9][a-z0-9-]{0,63}")
HEADING = re.compile(r"^(#{1,6})\s")
# $$...$$ (display) or $...$ (inline: no space inside either dollar, no blank line inside)
MATH = re.compile(
    r"\$\$(?P<display>.+?)\$\$|\$(?P<inline>[^\s$](?:(?:[^$\n]|\n(?!\s*\n))*?[^\s$])?)\$", re.S
)
TOKEN = "LMAPDMATH{}X"  # a placeholder markdown leaves as it is
DOCS_URL_ENV = "LMAPD_DOCS_URL"


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


@lru_cache(maxsize=512)
def math_html(latex: str, display: bool = False) -> str:
    """``latex`` as a MathML ``<math>`` element (``display``: a block of its own), or, where
    latex2mathml cannot read it, the formula as escaped code (never a traceback)."""
    from latex2mathml.converter import convert  # noqa: PLC0415 (loaded on the first "Read more")

    try:
        return convert(latex.strip(), display="block" if display else "inline")
    except Exception:  # latex2mathml raises its own errors, and IndexError on some input
        return f"<code>{html.escape(latex.strip())}</code>"


def markdown_html(markdown_text: str) -> str:
    """Markdown with ``$...$`` / ``$$...$$`` maths as HTML: the maths MathML, the rest
    ``markdown`` (tables, fenced code) where it is installed, else escaped text."""
    maths: list[str] = []

    def hold(m: re.Match) -> str:
        display = m.group("display") is not None
        maths.append(math_html(m.group("display") if display else m.group("inline"), display))
        token = TOKEN.format(len(maths) - 1)
        return f"\n\n{token}\n\n" if display else token

    text = MATH.sub(hold, markdown_text)
    try:
        import markdown  # noqa: PLC0415 (the docs' dependency: optional here)
    except ImportError:
        out = f"<p style='white-space: pre-wrap'>{html.escape(text)}</p>"
    else:
        out = markdown.markdown(text, extensions=["tables", "fenced_code"])
    for i, element in enumerate(maths):
        token = TOKEN.format(i)
        out = out.replace(f"<p>{token}</p>", element).replace(token, element)
    return out


def section_html(markdown_text: str) -> str:
    """A physics page section as HTML (its maths drawn): :func:`markdown_html`."""
    return markdown_html(markdown_text)


def docs_url(anchor: str, page: str = "physics") -> str:
    """Section ``anchor`` of a page of the documentation site (``LMAPD_DOCS_URL``, mkdocs'
    ``PAGE/`` address; default the physics page), or "" where no site is configured."""
    base = os.environ.get(DOCS_URL_ENV, "").strip().rstrip("/")
    if not base.startswith(("http://", "https://")):
        return ""
    return f"{base}/{page}/" + (f"#{anchor}" if anchor else "")


class PhysicsPage:
    """``physics_section`` on a trame state: what the dialog shows (None: the dialog is
    closed), and ``physics_available``: whether this installation has the physics page."""

    def __init__(self, state, path: Path = PHYSICS_MD, texts: dict[str, Any] | None = None):
        self.state = state
        self.path = path
        self.texts = texts or {}  # lesson key -> the Lesson (its read_more, title, reference)
        state.physics_section = None
        state.physics_available = bool(_lines(path))
        state.teaching_url = docs_url("", "teaching")  # the teacher's guide (the glossary links it)

    def read_more(self, key: Any = None, *_: Any, **__: Any) -> None:
        """Show lesson ``key``'s "Read more" (from the page: anything at all); an unknown one
        gives a message. Never raises."""
        lesson = self.texts.get(key) if isinstance(key, str) else None
        if lesson is None:
            self.state.input_message = "Read more: no such lesson"
            return
        anchor = lesson.reference.rsplit("#", 1)[-1]
        self.state.physics_section = {
            "kind": "reader",
            "key": lesson.key,
            "anchor": anchor,
            "title": lesson.reference_title,
            "html": markdown_html(lesson.read_more),
            "docs_url": docs_url(anchor),
            "full": bool(_lines(self.path)) and section_text(anchor, self.path) is not None,
        }

    def open(self, reference: Any = None, *_: Any, **__: Any) -> None:
        """Show the physics page's section ``reference`` names (``docs/physics.md#eq-29`` or
        ``eq-29``; from the page: anything at all); an unknown one gives a message. Never
        raises."""
        anchor = str(reference).rsplit("#", 1)[-1] if isinstance(reference, str) else ""
        found = section_text(anchor, self.path) if ANCHOR.fullmatch(anchor) else None
        if found is None:
            self.state.input_message = "Physics page: no such section"
            return
        title, text = found
        self.state.physics_section = {
            "kind": "physics",
            "key": "",
            "anchor": anchor,
            "title": title,
            "html": section_html(text),
            "docs_url": docs_url(anchor),
            "full": False,
        }

    def close(self, *_: Any, **__: Any) -> None:
        self.state.physics_section = None
